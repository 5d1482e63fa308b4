"""Plain `--help`: a flag shows no type after it, and a value is named by what it is, not its Python type.

Typer 0.2x prints a Python type after every option (`--strict <bool>`, `--seed <int>`,
`files... <list[Path]>`). People read `--strict` alone, `--seed SEED`, `--format text|json`, as
other command lines write them; this module teaches typer's parameter classes that, once, for
every command.
"""

from __future__ import annotations

from typing import Any

from typer import core


def _plain_type(param: Any, ctx: Any) -> str | None:
    if param.metavar is not None:
        return param.metavar
    if getattr(param, "is_flag", False):
        return None
    described = getattr(param, "type_descriptor", None)
    if described is not None and described.is_choice and described.choices:
        return "|".join(str(getattr(c, "value", c)) for c in described.choices)
    if isinstance(param, core.TyperArgument):
        return None  # its name already says it
    return (param.name or "value").upper()


def plain_help() -> None:
    """Make every command's help plain (a no-op on typer versions that print no types)."""
    for cls in (core.TyperOption, core.TyperArgument):
        if hasattr(cls, "display_type_rich"):
            cls.display_type_rich = _plain_type
