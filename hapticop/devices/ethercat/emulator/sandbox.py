"""A private network namespace with a veth pair and the emulated segment on one end.

The calling thread moves into a fresh network namespace (unshare CLONE_NEWNET), where only
loopback and the new veth pair exist: the master opens one end, the emulator process (its
child, so in the same namespace) answers on the other. Nothing outside is touched and
nothing is left: on exit the emulator stops, the pair is deleted, and the thread goes back
to the namespace it came from; the namespace goes with its last process.
Needs root (CAP_SYS_ADMIN for the namespace, CAP_NET_ADMIN for the links, CAP_NET_RAW for
the sockets). Links are made over netlink with pyroute2, so iproute2 need not be installed.
"""

from __future__ import annotations

import ctypes
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

__all__ = ["Sandbox", "namespace_problem", "MASTER_INTERFACE", "EMULATOR_INTERFACE"]

CLONE_NEWNET = 0x40000000
MASTER_INTERFACE = "hapticop-ecat0"
EMULATOR_INTERFACE = "hapticop-esc0"
_libc = ctypes.CDLL(None, use_errno=True)


def _unshare_net() -> None:
    if _libc.unshare(CLONE_NEWNET) != 0:
        error = ctypes.get_errno()
        raise PermissionError(error, f"cannot make a network namespace: {os.strerror(error)} (needs root)")


def _setns(fd: int) -> None:
    if _libc.setns(fd, CLONE_NEWNET) != 0:
        error = ctypes.get_errno()
        raise OSError(error, f"cannot return to the original network namespace: {os.strerror(error)}")


def namespace_problem() -> str | None:
    """Why a sandbox cannot be made here, or None if it can (tried in a throwaway thread)."""
    if not sys.platform.startswith("linux"):
        return "network namespaces need Linux"
    try:
        import pyroute2  # noqa: F401
    except ImportError:
        return "pyroute2 is not installed (pip install 'hapticop[ethercat]')"
    problem: list[str] = []

    def probe() -> None:
        try:
            _unshare_net()
            import socket

            socket.socket(socket.AF_PACKET, socket.SOCK_RAW, 0).close()
        except OSError as error:
            problem.append(f"no rights to make a network namespace and raw sockets ({error.strerror}); run as root")

    thread = threading.Thread(target=probe)
    thread.start()
    thread.join()
    return problem[0] if problem else None


class Sandbox:
    """`with Sandbox() as box:` the calling thread is in the namespace; `box.interface` is the master's end.

    `emulator=False` makes the pair without starting the emulator (an empty wire).
    """

    def __init__(self, interface: str = MASTER_INTERFACE, peer: str = EMULATOR_INTERFACE, emulator: bool = True,
                 seed: int = 0, truth: Path | None = None, priority: int = 45):
        self.interface, self.peer, self.start_emulator, self.seed = interface, peer, emulator, seed
        self.priority = priority  # the emulator stands in for hardware: above the application's threads
        # everything the emulator shares by file is the sandbox's own: sandboxes side by side (two test
        # workers) each have an interface of the same name, so no path may be derived from it
        self._dir = tempfile.TemporaryDirectory(prefix="hapticop-ecat-", dir="/dev/shm" if os.path.isdir("/dev/shm")
                                                else None)
        self.truth = truth if truth is not None else Path(self._dir.name) / "truth"
        self.control = Path(self._dir.name) / "control.sock"
        self.log = Path(self._dir.name) / "emulator.log"
        self.process: subprocess.Popen | None = None
        self._home: int | None = None

    def __enter__(self) -> Sandbox:
        self._home = os.open("/proc/thread-self/ns/net", os.O_RDONLY)
        try:
            _unshare_net()
        except BaseException:
            os.close(self._home)
            self._home = None
            raise
        try:
            self._links()
            if self.start_emulator:
                self._emulator()
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def _links(self) -> None:
        from pyroute2 import IPRoute

        with IPRoute() as ip:
            ip.link("add", ifname=self.interface, kind="veth", peer=self.peer)
            for name in ("lo", self.interface, self.peer):
                ip.link("set", index=ip.link_lookup(ifname=name)[0], state="up")

    def _emulator(self) -> None:
        command = [sys.executable, "-m", "hapticop.devices.ethercat.emulator", self.peer,
                   "--control", str(self.control), "--truth", str(self.truth), "--seed", str(self.seed),
                   "--priority", str(self.priority)]
        with open(self.log, "wb") as log:
            self.process = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT)
        from hapticop.devices.ethercat.emulator.server import control

        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"the EtherCAT emulator exited: {self.log.read_text().strip()}")
            if self.control.exists():
                try:
                    if control(self.control, {"op": "ping"}).get("ok"):
                        return
                except OSError:
                    pass
            time.sleep(0.02)
        raise RuntimeError("the EtherCAT emulator did not start within 20 s")

    def fault(self, op: str, **args) -> dict:
        """Send a fault or status request to the emulator; raises if it refuses."""
        from hapticop.devices.ethercat.emulator.server import control

        answer = control(self.control, {"op": op, **args})
        if not answer.get("ok"):
            raise RuntimeError(f"emulator refused {op}: {answer.get('error')}")
        return answer

    def __exit__(self, *exc) -> None:
        try:
            if self.process is not None and self.process.poll() is None:
                self.process.terminate()
                try:
                    self.process.wait(5.0)
                except subprocess.TimeoutExpired:
                    self.process.kill()
                    self.process.wait()
            try:
                from pyroute2 import IPRoute

                with IPRoute() as ip:
                    for index in ip.link_lookup(ifname=self.interface):
                        ip.link("del", index=index)
            except Exception:  # noqa: BLE001 - best-effort cleanup: the namespace takes the pair with it anyway
                pass
        finally:
            if self._home is not None:
                _setns(self._home)
                os.close(self._home)
                self._home = None
            self._dir.cleanup()
