"""Can an EtherCAT master run on this interface? Asked before a run starts, without opening it."""

from __future__ import annotations

import errno
import socket

ETH_P_ALL = 0x0003


def interface_problem(interface: str) -> str | None:
    """Why SOEM could not open `interface` (no such interface, no right to a raw socket), or None."""
    try:
        socket.if_nametoindex(interface)
    except OSError:
        return f"no network interface named '{interface}' for the EtherCAT segment (see `ip link`)"
    try:
        raw = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_ALL))
    except PermissionError:
        return f"opening '{interface}' for EtherCAT needs root or CAP_NET_RAW"
    except OSError as error:
        if error.errno in (errno.EAFNOSUPPORT, errno.EPROTONOSUPPORT):
            return "this system has no raw packet sockets for an EtherCAT master"
        return f"cannot open a raw socket for '{interface}': {error.strerror}"
    raw.close()
    try:
        import pysoem  # noqa: F401 - only whether it is there
    except ImportError:
        return "pysoem is not installed: pip install 'hapticop[hw]'"
    return None
