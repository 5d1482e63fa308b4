"""Is there a TiM5xx at this address? One blocking CoLa A conversation, for `hapticop devices`.

It asks what needs no login (docs/devices/sick-tim561.md §3): `sRI 0` (identity: device type and
firmware), `sRN SerialNumber` and `sRN SCdevicestate`, each answered before the next goes
out. Anything that goes wrong becomes a `ProbeError` that says which layer failed (name
resolution, routing, nobody listening, silence, not CoLa A) and what to check. Not for a
cycle: the cyclic client is `client.ColaClient`.
"""

from __future__ import annotations

import errno
import socket
import time
from dataclasses import dataclass

from hapticop.devices.sick import commands
from hapticop.devices.sick.cola import ColaDeviceError, ColaError
from hapticop.devices.sick.commands import Reply
from hapticop.devices.sick.stream import TelegramReader

__all__ = ["LidarIdentity", "ProbeError", "probe_lidar", "parse_identity", "DEVICE_STATES"]

DEVICE_STATES = {0: "busy", 1: "ready", 2: "error"}


@dataclass(frozen=True)
class LidarIdentity:
    host: str
    port: int
    device_type: str
    firmware: str
    serial: str | None
    state: str | None


class ProbeError(RuntimeError):
    """The address does not lead to a CoLa A scanner; the message says why and what to check."""


def parse_identity(reply: Reply) -> tuple[str, str]:
    """`sRA 0 6 TiM561 E V2.51-21.08.15` -> ("TiM561", "V2.51-21.08.15"); ColaError otherwise."""
    if reply.kind != b"sRA" or reply.name != b"0":
        raise ColaError(f"not an identity reply: {reply.kind.decode('latin-1')} {reply.name[:20]!r}")
    reader = reply.reader()
    device_type = reader.string("device type")
    version = reader.string("firmware version")
    reader.expect_end("the firmware version")
    return device_type.decode("latin-1"), version.decode("latin-1")


def _network_error(error: OSError, host: str, port: int, timeout_s: float) -> ProbeError:
    where = f"{host}:{port}"
    if isinstance(error, socket.gaierror):
        return ProbeError(f"cannot resolve {host!r}: {error.strerror}; give the scanner's IP address "
                          "(a TiM5xx's factory default is 192.168.0.1)")
    if isinstance(error, TimeoutError) or error.errno == errno.ETIMEDOUT:
        return ProbeError(f"no answer from {where} within {timeout_s:g} s: check the cable and the scanner's "
                          "power, and that this computer has an address on the scanner's subnet "
                          "(e.g. 192.168.0.10/24 for the factory default 192.168.0.1)")
    if error.errno == errno.ECONNREFUSED:
        return ProbeError(f"{where} refused the connection: a host is there but nothing listens on port {port} "
                          "(a TiM5xx speaks CoLa on 2112, also 2111); is it the scanner's address?")
    if error.errno in (errno.ENETUNREACH, errno.EHOSTUNREACH, errno.EADDRNOTAVAIL):
        return ProbeError(f"{where} is unreachable ({error.strerror}): this computer has no route to that "
                          "network; give the Ethernet port an address on the scanner's subnet")
    if error.errno in (errno.ECONNRESET, errno.EPIPE):
        return ProbeError(f"{where} closed the connection: the scanner serves one client at a time "
                          "(is a driver already connected?)")
    return ProbeError(f"network error talking to {where}: {error.strerror or error}")


def probe_lidar(host: str, port: int = 2112, timeout_s: float = 2.0) -> LidarIdentity:
    """Connect, ask identity, serial number and state, and close. ProbeError on any failure."""
    try:
        with socket.create_connection((host, port), timeout=timeout_s) as sock:
            reader = TelegramReader(max_telegram=4096)
            deadline = time.monotonic() + timeout_s

            def ask(kind: str, name: str, *params) -> Reply:
                sock.sendall(commands.request(kind, name, *params))
                while True:
                    for body in reader:
                        if body.startswith(b"sSN "):
                            continue  # a scan from an earlier subscription: not our answer
                        return commands.parse_reply(body, f"{kind} {name}")
                    left = deadline - time.monotonic()
                    if left <= 0:
                        raise TimeoutError
                    sock.settimeout(left)
                    chunk = sock.recv(4096)
                    if not chunk:
                        raise ConnectionResetError(errno.ECONNRESET, "connection closed")
                    reader.feed(chunk)

            try:
                device_type, firmware = parse_identity(ask("sRI", "0"))
            except TimeoutError:
                raise ProbeError(f"{host}:{port} accepted the connection but did not answer the CoLa A "
                                 "identity request `sRI 0` within {:g} s: is it set to CoLa B "
                                 "(binary)? SOPAS ET switches it back".format(timeout_s)) from None
            serial = state = None
            try:
                serial = ask("sRN", "SerialNumber").reader().string("serial number").decode("latin-1")
                code = ask("sRN", "SCdevicestate").reader().uint(8, "device state")
                state = DEVICE_STATES.get(code, f"unknown ({code})")
            except (ColaDeviceError, TimeoutError):
                pass  # identity is enough to say a scanner is there
    except ProbeError:
        raise
    except ColaDeviceError as error:
        raise ProbeError(f"{host}:{port} speaks CoLa A but refused the identity request: {error}") from None
    except ColaError as error:
        raise ProbeError(f"{host}:{port} answered, but not as a CoLa A scanner: {error}") from None
    except OSError as error:
        raise _network_error(error, host, port, timeout_s) from None
    return LidarIdentity(host, port, device_type, firmware, serial, state)
