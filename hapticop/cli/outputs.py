"""`-o -`: standard output, as Unix tools read a lone dash, for every command that writes a file.

A command writes to the path `written` yields; for `-` that is a temporary file (with the
suffix the writer infers its format from) copied to standard output once it is complete, so
no writer needs to know about streams and a failed write sends nothing half-made.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


def is_stdout(path: Path | None) -> bool:
    """`-o -` (or `--csv -`): the output is standard output."""
    return path is not None and str(path) == "-"


@contextmanager
def written(path: Path | None, suffix: str = "") -> Iterator[Path | None]:
    """Where to write `path`: itself (None: the command's default), or for `-` a temporary file sent
    to standard output afterwards."""
    if not is_stdout(path):
        yield path
        return
    with tempfile.TemporaryDirectory(prefix="hapticop-out-") as directory:
        temporary = Path(directory) / f"output{suffix}"
        yield temporary
        sys.stdout.flush()
        with open(temporary, "rb") as source:
            shutil.copyfileobj(source, sys.stdout.buffer)
        sys.stdout.buffer.flush()


def say_wrote(path: Path, detail: str = "") -> str:
    """The 'wrote PATH' line; for standard output it goes to standard error, out of the data's way."""
    return f"wrote {'standard output' if is_stdout(path) else path}{detail}"
