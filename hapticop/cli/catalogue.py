"""`hapticop blocks`: every block an author can name, with its ports, flags, rate and parameters."""

from __future__ import annotations

import json

import typer


def blocks(
    names: list[str] = typer.Argument(None, help="blocks to describe (built-in names or package.module:Class); "
                                                 "default: every built-in and installed block"),
    json_output: bool = typer.Option(False, "--json", help="the catalogue as JSON"),
    markdown: bool = typer.Option(False, "--markdown", help="the catalogue as the Markdown of docs/blocks.md"),
) -> None:
    """List blocks with their ports (dtype, shape, unit), flags, rate range and parameters."""
    from hapticop.blocks.catalogue import catalogue, to_markdown

    entries = catalogue(names or None)
    if json_output:
        typer.echo(json.dumps([e.to_json() for e in entries], indent=2, default=str))
    elif markdown:
        typer.echo(to_markdown(entries), nl=False)
    elif names:
        for entry in entries:
            _detail(entry)
    else:
        width = max(len(e.name) for e in entries)
        for entry in entries:
            typer.echo(f"{entry.name:<{width}}  {entry.error or entry.summary}")
        typer.echo("\n`hapticop blocks NAME` for one block's ports, flags and parameters; --json, --markdown")
    if any(e.error for e in entries):
        raise typer.Exit(1)


def _detail(entry) -> None:
    typer.echo(f"{entry.name} ({entry.target}, {entry.origin})")
    if entry.error:
        typer.echo(f"  cannot be described: {entry.error}")
        return
    typer.echo(f"  {entry.summary}")
    typer.echo(f"  rate: {entry.rate}")
    for title, ports in (("input", entry.inputs), ("output", entry.outputs)):
        for name, p in ports.items():
            optional = " (optional)" if not p["required"] else ""
            typer.echo(f"  {title} {name}: {p['dtype']}{list(p['shape'])} [{p['unit']}]{optional} {p['doc']}".rstrip())
    for title, flags in (("reads flag", entry.flags_read), ("writes flag", entry.flags_written)):
        for name, doc in flags.items():
            typer.echo(f"  {title} {name}: {doc}")
    for param, provides in entry.needs.items():
        typer.echo(f"  needs: parameter '{param}' names an activity providing {provides}")
    for p in entry.parameters:
        unit = f" [{p.unit}]" if p.unit else ""
        variant = f" ({p.variant})" if p.variant else ""
        value = f" = {json.dumps(p.default, default=str)}" if p.default != "" else ""  # a set: its keys follow
        typer.echo(f"  {'  ' * p.depth}param {p.name}{variant}: {p.type}{value}{unit} ({p.live})"
                   + (f" - {p.description}" if p.description else ""))
