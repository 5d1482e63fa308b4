"""Where a run leaves its logs and results: per user, private, and not without bound.

Runs default to a tmpfs (`/dev/shm`, else `/tmp`), where every user can create names, so each
user gets a directory of their own (`hapticop-<uid>`) that only they can enter. A directory of
that name that is not theirs, or not a directory (a symlink planted there), is refused rather
than written into; the control socket's default directory is made the same way. Only the newest
`keep` default run directories are kept: every run leaves a few megabytes on memory-backed
storage. With `group` (`hapticop compose --group-readable`) the directories are 0750 instead of
0700, so the owner's group may read the runs (the files are then written with umask 027).
"""

from __future__ import annotations

import os
import re
import shutil
import stat
import time
from pathlib import Path

KEEP_RUNS = 20  # default run directories kept per user; HAPTICOP_KEEP_RUNS overrides
_RUN_NAME = re.compile(r".+-\d{8}-\d{6}-\d+\Z")


class RunDirectoryError(RuntimeError):
    """A run directory cannot be made safely; the message says which and why."""


def private_directory(path: Path, mode: int = 0o700, option: str = "--run-dir") -> Path:
    """`path` as a directory of its owner's with exactly `mode` (0700: theirs alone, 0750: their
    group may read): made so, or checked to be theirs and set so. `option` is what the user may
    give instead, named when the directory is refused."""
    try:
        os.mkdir(path, mode)
    except FileExistsError:
        pass
    except OSError as error:
        raise RunDirectoryError(f"cannot make the directory {path}: {error.strerror}") from None
    info = os.lstat(path)  # a symlink is not followed: it is refused below
    if not stat.S_ISDIR(info.st_mode):
        raise RunDirectoryError(f"{path} is not a directory (a link or a file is there): not writing into it")
    if info.st_uid != os.geteuid():
        raise RunDirectoryError(f"{path} belongs to user {info.st_uid}, not to you: not writing into it "
                                f"(remove it, or give {option})")
    if stat.S_IMODE(info.st_mode) != mode:
        os.chmod(path, mode)  # mkdir's mode passed through the umask; an older directory may be open
    return path


def directory_mode(group: bool) -> int:
    return 0o750 if group else 0o700


def user_runs_directory(group: bool = False) -> Path:
    """This user's directory of runs on the tmpfs (made if need be)."""
    shm = Path("/dev/shm")
    base = shm if shm.is_dir() and os.access(shm, os.W_OK) else Path("/tmp")
    return private_directory(base / f"hapticop-{os.geteuid()}", directory_mode(group))


def keep_runs() -> int:
    try:
        return max(0, int(os.environ.get("HAPTICOP_KEEP_RUNS", KEEP_RUNS)))
    except ValueError:
        return KEEP_RUNS


def new_run_directory(name: str, keep: int | None = None, group: bool = False) -> Path:
    """A fresh default run directory for `name`, the oldest runs beyond `keep` removed first."""
    parent = user_runs_directory(group)
    prune_runs(parent, (keep_runs() if keep is None else keep) - 1)
    return private_directory(parent / f"{name}-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}",
                             directory_mode(group))


def prune_runs(parent: Path, keep: int) -> list[Path]:
    """Remove all but the newest `keep` run directories in `parent` (only names runs are given,
    never a link); the ones removed."""
    runs = []
    for entry in os.scandir(parent):
        if _RUN_NAME.match(entry.name) and entry.is_dir(follow_symlinks=False):
            runs.append((entry.stat(follow_symlinks=False).st_mtime_ns, Path(entry.path)))
    runs.sort()
    removed = [path for _, path in runs[:max(len(runs) - max(keep, 0), 0)]]
    for path in removed:
        shutil.rmtree(path, ignore_errors=True)
    return removed
