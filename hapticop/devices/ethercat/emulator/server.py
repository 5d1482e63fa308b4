"""The emulated segment on a network interface: raw EtherCAT frames in, processed frames out.

One process, one loop: receive a frame of EtherType 0x88A4 on the interface (an AF_PACKET
socket does not see its own transmissions, so a veth peer is a wire), let the segment
process it, send it back; between frames, expire watchdogs and step the robot's physics
about every millisecond, and publish where the robot is. It must not share a process with
pysoem, which holds the GIL inside several of its calls.

Faults arrive over a Unix socket as JSON lines and run between two frames:
`{"op": "lose", "slave": 5}` (power off: it and every slave wired behind it fall off the
segment), `restore` (power back: freshly powered, in INIT), `cut` (the cable into that slave:
it and those behind keep power and state but no frame reaches them), `reconnect`,
`al_error` with a `code` (and `hold_ms`: the cause persists that long), `trip_watchdog`,
`late` (`delay_us` for the next `frames` frames), `lose_mailbox_reply` (the next `frames`
frames that carry an answer out of that slave's mailbox are processed but never come back:
the answer left SM1 and the master must ask for it again), `physics` (`run`: false freezes the robot,
so its sensors stay put), `status` (states, codes, which slaves a frame reaches, the wheels'
process-data buffers in hex and each wheel's drive as it truly is, the robot's pose), `ping`,
`stop`. Slaves are named by bus position, 0-based; a request that makes no sense (no such
slave, power back on a slave that has it, a cable that is not cut) is answered with an error.
"""

from __future__ import annotations

import json
import os
import queue
import select
import socket
import threading
import time
from pathlib import Path

from hapticop.devices.ethercat.emulator.esc import REG_WD_STATUS
from hapticop.devices.ethercat.emulator.ropod_segment import RopodSegment
from hapticop.devices.ethercat.emulator.segment import ETHERTYPE
from hapticop.devices.ethercat.emulator.truth import TruthWriter
from hapticop.devices.ropod.pdo import Stat1, txpdo_view

__all__ = ["FrameServer", "control"]

STEP_NS = 1_000_000
MAX_REQUEST_BYTES = 64 * 1024  # a fault request is a few dozen bytes


class FrameServer:
    def __init__(self, interface: str, model: RopodSegment, control_path: Path | None = None,
                 truth_path: Path | None = None, log=print):
        self.interface, self.model = interface, model
        self.control_path = Path(control_path) if control_path else None
        self.truth_path = Path(truth_path) if truth_path else None
        self.log = log
        self.requests: queue.SimpleQueue = queue.SimpleQueue()
        self.running = True
        self.late_us = 0
        self.late_frames = 0
        self.mailbox_losses: dict[int, int] = {}  # bus position -> reply frames still to lose
        self.physics = True
        self.started_ns = 0

    # --- the loop ----------------------------------------------------------------------
    def run(self) -> None:
        sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETHERTYPE))
        try:
            sock.bind((self.interface, ETHERTYPE))
        except OSError as error:
            sock.close()
            raise OSError(f"cannot open EtherCAT interface '{self.interface}': {error}") from None
        truth = TruthWriter(self.truth_path) if self.truth_path else None
        listener = self._listen() if self.control_path else None
        buffer = bytearray(1518)
        view = memoryview(buffer)
        model, segment = self.model, self.model.segment
        self.started_ns = now = time.monotonic_ns()
        next_step = now
        self.log(f"emulated segment on {self.interface}: {', '.join(s.name for s in model.slaves)}")
        try:
            while self.running:
                wait = max(next_step - time.monotonic_ns(), 0) / 1e9
                ready, _, _ = select.select([sock], [], [], wait)
                now = time.monotonic_ns()
                if ready:
                    n = sock.recv_into(buffer)
                    taken = self._answers_taken()
                    if n > 16 and buffer[12] == 0x88 and buffer[13] == 0xA4 and segment.process(view[14:n], now):
                        buffer[6] |= 0x02  # an ESC marks the source address of a frame it returns
                        if self.mailbox_losses and self._lose_reply(taken):
                            continue
                        if self.late_frames:
                            self.late_frames -= 1
                            time.sleep(self.late_us / 1e6)
                        sock.send(view[:n])
                if now >= next_step:
                    model.tick(now)
                    if self.physics:
                        model.step(now)
                    if truth is not None:
                        truth.write((now - self.started_ns) / 1e9, model.plant.pose, model.plant.twist)
                    next_step = max(next_step + STEP_NS, now)
                self.answer_requests()
        finally:
            sock.close()
            if truth is not None:
                truth.close()
            if listener is not None:
                listener.close()
                self.control_path.unlink(missing_ok=True)

    def _answers_taken(self) -> list[int] | None:
        if not self.mailbox_losses:
            return None
        return [s.mailbox.taken if s.mailbox is not None else 0 for s in self.model.slaves]

    def _lose_reply(self, before: list[int] | None) -> bool:
        """Whether this frame carried an answer out of a mailbox whose replies are to be lost."""
        for position, left in list(self.mailbox_losses.items()):
            mailbox = self.model.slaves[position].mailbox
            if before is not None and mailbox.taken != before[position]:
                if left <= 1:
                    del self.mailbox_losses[position]
                else:
                    self.mailbox_losses[position] = left - 1
                return True
        return False

    def answer_requests(self) -> None:
        """The control requests that arrived, answered between two frames (the loop's own thread)."""
        while not self.requests.empty():
            request, reply = self.requests.get_nowait()
            reply.put(self._handle(request))

    # --- faults and status -------------------------------------------------------------
    def _position(self, request: dict) -> int:
        position = request.get("slave")
        count = len(self.model.slaves)
        if type(position) is not int or not 0 <= position < count:
            raise ValueError(f"'slave' must be a bus position, an integer 0-{count - 1}; got {repr(position)[:40]}")
        return position

    def _slave(self, request: dict):
        return self.model.slaves[self._position(request)]

    def _wheels(self) -> list[dict]:
        """Each wheel's drive as it truly is: applies its outputs, both motors enabled, their currents."""
        status1 = txpdo_view(self.model.tx)["status1"]
        return [{"live": w.outputs_live, "watchdog": w.mem[REG_WD_STATUS] & 1,
                 "enabled": bool(status1[i] & Stat1.ENABLED1 and status1[i] & Stat1.ENABLED2),
                 "current_a": self.model.plant.currents_hw[2 * i:2 * i + 2].tolist()}
                for i, w in enumerate(self.model.wheels)]

    def _handle(self, request: dict) -> dict:
        try:
            op = request.get("op")
            if op == "ping":
                return {"ok": True, "frames": self.model.segment.frames}
            if op == "status":
                segment = self.model.segment
                return {"ok": True, "frames": segment.frames, "slaves": [
                    {"name": s.name, "present": s.present, "reached": reached, "state": s.state,
                     "al_status": s.al_status, "al_code": s.al_code, "station": s.station,
                     "watchdog_ns": s.watchdog_ns()}
                    for s, reached in zip(self.model.slaves, segment.reached())],
                    "cut": sorted(segment.cut), "wheels": self._wheels(),
                    "outputs": [bytes(w.output_buffer() or b"").hex() for w in self.model.wheels],
                    "inputs": [bytes(w.input_buffer() or b"").hex() for w in self.model.wheels],
                    "pose": self.model.plant.pose.tolist(), "twist": self.model.plant.twist.tolist()}
            if op == "lose":
                slave = self._slave(request)
                if not slave.present:
                    raise ValueError(f"slave {request['slave']} is already powered off")
                slave.present = False
            elif op == "restore":
                slave = self._slave(request)
                if slave.present:
                    raise ValueError(f"slave {request['slave']} has power ('lose' it first)")
                slave.power_on()
                slave.present = True
            elif op == "cut":
                position = self._position(request)
                if position in self.model.segment.cut:
                    raise ValueError(f"the cable into slave {position} is already cut")
                self.model.segment.cut.add(position)
            elif op == "reconnect":
                position = self._position(request)
                if position not in self.model.segment.cut:
                    raise ValueError(f"the cable into slave {position} is not cut")
                self.model.segment.cut.discard(position)
            elif op == "al_error":
                hold_ns = int(float(request.get("hold_ms", 0)) * 1e6)
                self._slave(request).raise_error(int(request["code"]), until_ns=time.monotonic_ns() + hold_ns)
            elif op == "trip_watchdog":
                self._slave(request).trip_watchdog()
            elif op == "late":
                self.late_us, self.late_frames = int(request["delay_us"]), int(request["frames"])
            elif op == "lose_mailbox_reply":
                position = self._position(request)
                if self.model.slaves[position].mailbox is None:
                    raise ValueError(f"slave {position} has no mailbox")
                frames = request.get("frames", 1)
                if type(frames) is not int or frames < 1:
                    raise ValueError(f"'frames' must be a positive integer; got {repr(frames)[:40]}")
                self.mailbox_losses[position] = frames
            elif op == "physics":
                self.physics = bool(request["run"])
                self.model.last_step_ns = None  # no leap in time when it runs again
            elif op == "stop":
                self.running = False
            else:
                raise ValueError(f"unknown operation {op!r}")
            self.log(f"fault: {json.dumps(request)}")
            return {"ok": True}
        except (KeyError, ValueError, TypeError, OverflowError) as error:
            return {"ok": False, "error": str(error)}
        except Exception as error:  # noqa: BLE001 - no request may stop the segment's loop
            return {"ok": False, "error": f"{type(error).__name__}: {error}"}

    def _listen(self) -> socket.socket:
        self.control_path.unlink(missing_ok=True)
        listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        listener.bind(str(self.control_path))
        os.chmod(self.control_path, 0o600)
        listener.listen(4)
        threading.Thread(target=self._serve, args=(listener,), daemon=True, name="ecat-control").start()
        return listener

    def _serve(self, listener: socket.socket) -> None:
        while self.running:
            try:
                connection, _ = listener.accept()
            except OSError:
                return
            threading.Thread(target=self._client, args=(connection,), daemon=True).start()

    def _client(self, connection: socket.socket) -> None:
        """One client's requests, a JSON object a line. Whatever else arrives gets an error and
        never reaches the loop: a bad request must not take the emulated segment down with it."""
        with connection, connection.makefile("rwb") as stream:
            while line := stream.readline(MAX_REQUEST_BYTES + 1):
                whole = line.endswith(b"\n") or len(line) <= MAX_REQUEST_BYTES
                answer = self._request(line) if whole else {
                    "ok": False, "error": f"a request is one line of at most {MAX_REQUEST_BYTES} bytes"}
                stream.write((json.dumps(answer) + "\n").encode())
                stream.flush()
                if not whole:
                    return  # the rest of that line cannot be told from a next request

    def _request(self, line: bytes) -> dict:
        try:
            request = json.loads(line)
        except (ValueError, RecursionError) as error:  # not JSON, not UTF-8, or nested past Python's stack
            return {"ok": False, "error": f"not JSON: {str(error)[:200]}"}
        if not isinstance(request, dict):
            return {"ok": False, "error": 'a request is a JSON object, e.g. {"op": "status"}'}
        reply: queue.SimpleQueue = queue.SimpleQueue()
        self.requests.put((request, reply))
        try:
            return reply.get(timeout=5.0)
        except queue.Empty:
            return {"ok": False, "error": "the emulator loop did not answer"}


def control(path: Path, request: dict, timeout: float = 5.0) -> dict:
    """Send one request to a running emulator's control socket and return its answer."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
        sock.settimeout(timeout)
        sock.connect(str(path))
        sock.sendall((json.dumps(request) + "\n").encode())
        answer = b""
        while not answer.endswith(b"\n"):
            chunk = sock.recv(65536)
            if not chunk:
                raise ConnectionError(f"the emulator at {path} closed the connection")
            answer += chunk
    return json.loads(answer)
