"""Checks of the link's security: keys named, there, each host's own, valid today and private, and
endpoints that speak TLS; or an explicit 'insecure: true', which is said aloud (docs/security.md).

The key directory is resolved against the file that names it (a file extending teleop.yaml uses
teleop.yaml's keys). Every host's certificate is checked; a host's private key where it is present
(a deployed host has only its own, which its bridge checks again before the run starts), and
missing only when the directory holds no host's private key at all.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from hapticop.composition.description import Composition
from hapticop.composition.diagnostics import Diagnostic, Severity
from hapticop.composition.yamlsource import Source
from hapticop.network import keys

SECURE_PROTOCOLS = ("tls", "quic")


def key_directory(source: Source, composition: Composition) -> Path | None:
    """The directory `security.keys` names, relative to the file that names it; None without one."""
    named = composition.security.keys
    if named is None:
        return None
    owner = source.place(Diagnostic("security-keys", "", ("security", "keys"))).file or source.file
    return (Path(owner).parent / named).resolve()


def check(source: Source, composition: Composition) -> Iterator[Diagnostic]:
    if not composition.hosts:
        return
    security = composition.security
    if security.insecure:
        yield Diagnostic("security-insecure", "the hosts' link is insecure: anyone who reaches a host may join it, "
                         "read every stream and drive the robot", ("security", "insecure"), Severity.WARNING,
                         hint="name keys instead ('security: {keys: DIR}', `hapticop hosts keys FILE`)")
        return
    directory = key_directory(source, composition)
    if directory is None:
        yield Diagnostic("security-keys", "the hosts' link names no keys: it would be open to anyone who reaches "
                         "a host", ("hosts",), hint="`hapticop hosts keys FILE` makes them; then "
                         "'security: {keys: DIR}' (or 'insecure: true' on a closed test network)")
        return
    for name, host in composition.hosts.items():
        for i, endpoint in enumerate(host.endpoints):
            if endpoint.split("/", 1)[0] not in SECURE_PROTOCOLS:
                yield Diagnostic("security-endpoint", f"host '{name}' listens on '{endpoint}', which carries no "
                                 "TLS: the keys would protect nothing there", ("hosts", name, "endpoints", i),
                                 hint=f"'tls/{endpoint.split('/', 1)[1]}'")
    any_private = any(keys.files(directory, h).key.exists() for h in composition.hosts)
    for name, host in composition.hosts.items():
        present = keys.files(directory, name).key.exists()
        addresses = [keys.endpoint_address(e) for e in host.endpoints]
        for path, soon in keys.ending_soon(directory, name):
            yield Diagnostic("security-expiry", f"host '{name}': {path} {soon}", ("security", "keys"),
                             Severity.WARNING, hint="renew the keys before then (docs/security.md, 'Rotation')")
        for path, problem in keys.problems(directory, name, addresses, private=present or not any_private):
            yield Diagnostic("security-keys", f"host '{name}': {path} {problem}", ("security", "keys"),
                             hint=f"`hapticop hosts keys FILE{' --force' if 'missing' not in problem else ''}` "
                             "makes the missing ones (docs/security.md)")
