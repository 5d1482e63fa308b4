"""`hapticop docs`: the documentation pages made from the code, so they cannot drift from it.

Three pages are generated: the command-line reference from the commands' own parser, the
composition format reference from the JSON Schema (itself made from the pydantic models), and the
block catalogue from the blocks' declarations. A test fails while a committed page differs.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import typer

DOCS = Path(__file__).resolve().parents[2] / "docs"

# The format's own models, in reading order; block parameter models are the catalogue's.
FORMAT_MODELS = [
    "Thread", "Activity", "Stream", "LatestPolicy", "QueuePolicy", "Coordination", "StandardCoordination",
    "PetriNet", "Place", "Transition", "FlagMap", "Mode", "ScriptedPatch", "Latency", "Record",
    "Host", "Security", "NetworkQoS", "LinkParams", "Ros2System", "Ros2Flags", "Ros2Stream", "Ros2Qos", "ScanParams",
]


def cli_reference(root: Any) -> str:
    """Every command and option under `root` (the `hapticop` command), as `--help` shows them."""
    lines = ["# Command-line reference", "",
             "Generated from the commands themselves by `hapticop docs`; `hapticop COMMAND --help` says the same.",
             ""]
    for path, command, context in _commands(root, root.context_class(root, info_name="hapticop")):
        lines += [f"## `{' '.join(path)}`", "", _first_paragraph(command.help or ""), "",
                  "```text", context.command.get_usage(context).removeprefix("Usage: "), "```", ""]
        records = [p.get_help_record(context) for p in command.get_params(context)]
        records = [r for r in records if r is not None and r[0] != "--help"]
        if hasattr(command, "commands"):
            records += [(name, _first_paragraph(sub.help or "")) for name, sub in sorted(command.commands.items())
                        if not sub.hidden]
        if records:
            lines += ["| | |", "|---|---|"]
            lines += [f"| {_code(name)} | {_cell(text)} |" for name, text in records]
            lines.append("")
    return "\n".join(lines).rstrip() + "\n"


def _commands(command: Any, context: Any,
              path: tuple[str, ...] = ("hapticop",)) -> Iterator[tuple[tuple[str, ...], Any, Any]]:
    """Every command under `command` with a parsing context of its own (typer's click, whichever it is)."""
    yield path, command, context
    for name in sorted(getattr(command, "commands", {})):
        sub = command.commands[name]
        if not sub.hidden:
            yield from _commands(sub, sub.context_class(sub, info_name=name, parent=context), (*path, name))


def _first_paragraph(text: str) -> str:
    return " ".join(text.strip().split("\n\n")[0].split())


def _code(text: str) -> str:
    """Code in a table cell; a `|` cannot sit in a code span there (GitHub and MkDocs disagree): plain, escaped."""
    if "|" not in text:
        return f"`{_cell(text)}`"
    return _cell(text).replace("<", "&lt;").replace(">", "&gt;")


def _cell(text: str) -> str:
    return " ".join(text.split()).replace("|", "\\|")


def composition_reference(root: Any = None) -> str:
    """Every entry of a composition file: its type, default and meaning, from the JSON Schema."""
    from hapticop.composition.schema import composition_schema

    schema = composition_schema()
    defs = schema["$defs"]
    lines = ["# Composition format reference", "",
             "Generated from the format's models (`hapticop/composition/description.py`) through the JSON Schema",
             "(`schemas/composition.schema.json`) by `hapticop docs`. A guide with an example of every entry:",
             "[the composition file](../composition.md); each block's `params`: [the block catalogue](../blocks.md).",
             "", "Times and rates are strings with their unit (`1ms`, `250us`, `15Hz`); names are lower_snake_case.",
             ""]
    lines += _model_section("Composition", schema, defs)
    for name in FORMAT_MODELS:
        lines += _model_section(name, defs[name], defs)
    return "\n".join(lines).rstrip() + "\n"


def _model_section(name: str, model: dict, defs: dict) -> list[str]:
    """One model's fields as a table; the heading's anchor (its name in lower case) is what links use."""
    from hapticop.blocks.catalogue import unit_of

    required = set(model.get("required", []))
    lines = [f"## {name}", ""]
    if name == "Composition":
        lines += ["The file itself.", ""]
    elif model.get("description"):
        lines += [" ".join(model["description"].split()), ""]
    lines += ["| key | type | default | |", "|---|---|---|---|"]
    for key, field in model.get("properties", {}).items():
        default = "required" if key in required else _default(field)
        kind = _type(field, defs)
        unit = unit_of(key) if field.get("type") in ("number", "integer") else ""
        lines.append(f"| `{key}` | {_cell(kind + (f' ({unit})' if unit else ''))} | {_cell(default)} | "
                     f"{_cell(field.get('description', ''))} |")
    return lines + [""]


def _default(field: dict) -> str:
    if "default" not in field:
        return ""
    value = field["default"]
    return "" if value is None else f"`{value!r}`" if not isinstance(value, str) else f"`{value}`" if value else "`''`"


def _type(field: dict, defs: dict) -> str:
    """A field's type in words, with a link to the section of a model it refers to."""
    if "$ref" in field:
        name = field["$ref"].rsplit("/", 1)[-1]
        return f"[{name}](#{name.lower()})" if name in FORMAT_MODELS else name
    options = field.get("anyOf") or field.get("oneOf")
    if options:
        kinds = [_type(option, defs) for option in options if option.get("type") != "null"]
        return " or ".join(dict.fromkeys(kinds)) or "null"
    if "const" in field:
        return f"`{field['const']}`"
    if "enum" in field:
        return "one of " + ", ".join(f"`{value}`" for value in field["enum"])
    kind = field.get("type")
    if kind == "array":
        return "list of " + _type(field.get("items", {}), defs) if field.get("items") else "list"
    if kind == "object":
        for values in field.get("patternProperties", {}).values():
            return "mapping of names to " + _type(values, defs)
        values = field.get("additionalProperties")
        return "mapping to " + _type(values, defs) if isinstance(values, dict) else "mapping"
    if kind == "string" and "pattern" in field and "Hz" in field["pattern"]:
        return "time or rate"
    if kind == "string" and "pattern" in field and "ms" in field["pattern"]:
        return "time"
    return {"string": "text", "integer": "integer", "number": "number", "boolean": "true or false",
            "null": "null"}.get(kind, kind or "any")


def blocks_reference(root: Any = None) -> str:
    from hapticop.blocks.catalogue import catalogue, to_markdown
    from hapticop.blocks.registry import BUILTIN

    return to_markdown(catalogue(list(BUILTIN)))


# Each page made from the `hapticop` command (only the CLI reference reads it; passed in, as this
# module is itself one of the commands).
PAGES: dict[str, Callable[[Any], str]] = {
    "reference/cli.md": cli_reference,
    "reference/composition.md": composition_reference,
    "blocks.md": blocks_reference,
}


def docs(context: typer.Context,
         check: bool = typer.Option(False, "--check", help="write nothing; fail if a page is not current")) -> None:
    """Write the documentation pages generated from the code (CLI, composition format, blocks)."""
    if not DOCS.is_dir():
        typer.echo(f"error: no {DOCS}: the pages are written into a checkout of hapticop (pip install -e)", err=True)
        raise typer.Exit(2)
    stale = []
    for name, make in PAGES.items():
        path = DOCS / name
        text = make(context.find_root().command)
        if path.exists() and path.read_text() == text:
            continue
        stale.append(name)
        if not check:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text)
            typer.echo(f"wrote docs/{name}")
    if check and stale:
        typer.echo(f"not current: {', '.join(stale)}; run `hapticop docs`", err=True)
        raise typer.Exit(1)
