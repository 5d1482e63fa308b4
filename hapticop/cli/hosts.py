"""`hapticop compose` for a composition on several hosts: one side (`--host`), or every side here;
and `hapticop hosts keys`, the link's key material (docs/security.md).

Each host runs a runtime of its own, so "every side here" is one `hapticop compose FILE --host H`
child per host, each in a run directory of its own under one parent. The simulated world and its
operator may sit on different hosts and find each other through the run directory's published facts
(`hapticop.published`), so the children share those. When one side ends, the others are given a
grace period to see it through their bridges and end too, then are interrupted; Ctrl+C interrupts all.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import typer

hosts = typer.Typer(help="Compositions on several hosts: the link's keys.", no_args_is_help=True,
                    add_completion=False)

FACT_KINDS = ("operators", "worlds", "links")  # what `hapticop.published` keeps under a run directory
GRACE_S = 10.0


def run_every_host(file: Path, hosts: list[str], parent: Path, passed: list[str]) -> int:
    """Run each host's side as a child beside the others; the worst exit status of them."""
    shared = parent / "facts"
    children: dict[str, subprocess.Popen] = {}
    for host in hosts:
        run_dir = parent / host
        run_dir.mkdir(mode=0o700, exist_ok=True)
        for kind in FACT_KINDS:
            (shared / kind).mkdir(parents=True, exist_ok=True)
            link = run_dir / kind
            if not link.exists():
                link.symlink_to(shared / kind, target_is_directory=True)
        children[host] = subprocess.Popen(
            [sys.executable, "-m", "hapticop.cli", "compose", str(file), "--host", host, "--run-dir", str(run_dir),
             *passed], start_new_session=True)

    def interrupt(*_: object) -> None:
        for child in children.values():
            if child.poll() is None:
                os.killpg(child.pid, signal.SIGINT)

    previous = {s: signal.signal(s, interrupt) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        ended_at = None
        while any(child.poll() is None for child in children.values()):
            if ended_at is None and any(child.poll() is not None for child in children.values()):
                ended_at = time.monotonic()
            if ended_at is not None and time.monotonic() - ended_at > GRACE_S:
                interrupt()
                ended_at = float("inf")
            time.sleep(0.1)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    return max(child.returncode for child in children.values())


@hosts.command("keys")
def make_keys(
    file: Path = typer.Argument(..., help="a composition with 'hosts:'"),
    force: bool = typer.Option(False, "--force", help="replace every host's key and certificate (rotation)"),
    new_ca: bool = typer.Option(False, "--new-ca", help="with --force, a new CA too: every host needs new files"),
    days: int = typer.Option(365, min=1, help="how long the certificates are valid"),
) -> None:
    """Make the link's keys: a CA, and each host's key and certificate (its name, its addresses), files 0600.

    They go in the directory 'security.keys' names, or FILE's stem + '.keys' beside it; files already
    there are kept unless --force."""
    if new_ca and not force:
        typer.echo("--new-ca replaces the CA every host trusts: give --force too", err=True)
        raise typer.Exit(2)
    try:
        said = keys_for(file, force, new_ca, days)
    except (ValueError, FileExistsError) as error:
        typer.echo(f"{file}: {error}", err=True)
        raise typer.Exit(2) from None
    for line in said:
        typer.echo(line)


def keys_for(file: Path, force: bool = False, new_ca: bool = False, days: int = 365) -> list[str]:
    """The keys of `file`'s hosts made where it names them (what `hapticop hosts keys` does); what was done."""
    from hapticop.network import keys
    from hapticop.validation import validate_path
    from hapticop.validation.security import key_directory

    validated = validate_path(file)
    composition = validated.graph.loaded.composition if validated.graph is not None else None
    if composition is None or not composition.hosts:
        raise ValueError("no composition with 'hosts:' to make keys for")
    directory = key_directory(validated.source, composition) or file.resolve().parent / f"{file.stem}.keys"
    directory.mkdir(mode=0o700, parents=True, exist_ok=True)
    said = []
    if new_ca or not (directory / "ca.pem").exists():
        keys.make_ca(directory, composition.name or file.stem, days, force=new_ca)
        said.append(f"{directory / 'ca.pem'}: a new CA (its key, ca.key, signs the hosts': keep it off them)")
    for name, host in composition.hosts.items():
        where = keys.files(directory, name)
        if force or new_ca or not (where.certificate.exists() or where.key.exists()):
            keys.make_host(directory, name, [keys.endpoint_address(e) for e in host.endpoints], days,
                           force=force or new_ca)
            said.append(f"{where.certificate}, {where.key.name}: host '{name}'")
        else:
            said.append(f"{where.certificate}: kept (--force replaces it)")
        said.extend(f"warning: {path} {soon}" for path, soon in keys.ending_soon(directory, name))
    if composition.security.keys is None:
        said.append(f"now name them in {file}: 'security: {{keys: {directory.name}}}'")
    return said
