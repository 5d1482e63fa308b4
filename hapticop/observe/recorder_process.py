"""Where the recorder runs: a process of its own on the wall clock, the main process under the virtual clock.

On the wall clock the recorder is a process at normal scheduling, which leaves with its parent
and hears from it over a pipe (stop, a stream a patch added, an event); under the virtual clock
the main process drains the rings itself between two main-thread cycles, so a test's recording
is the same every run. Both are handles with the same calls, which `observation` uses.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import signal
import threading
import time
from collections.abc import Callable
from multiprocessing import shared_memory

from hapticop.observe.recorder import RecordedRing, Recorder, RecorderPlan, ring_of, rings_of, sources_of
from hapticop.recording.live import LiveViewUnavailable

PR_SET_PDEATHSIG = 1
RECORDER_NICE = -5
"""Normal scheduling (SCHED_OTHER), weighted above ordinary processes so that a busy machine
does not starve it for longer than its rings hold; the real-time loops preempt it all the same."""


# -- on the wall clock: a process of its own ---------------------------------------------------

def record_main(plan: RecorderPlan, region_name: str, parent: int, messages) -> None:
    """The recorder process: drain every `DRAIN_INTERVAL_NS` until the parent says stop (or
    dies: the file is finished all the same), then send the parent the summary."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl+C is the parent's: it stops us when the loops are done
    orphaned = threading.Event()

    def terminated(_signum=None, _frame=None) -> None:
        if os.getppid() != parent:  # the parent died (PR_SET_PDEATHSIG): finish what we have
            orphaned.set()  # a SIGTERM to the whole group while the parent lives: it stops us in order

    signal.signal(signal.SIGTERM, terminated)
    libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
    if os.getppid() != parent:
        orphaned.set()
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))  # never real time, whatever it inherited
    try:
        os.setpriority(os.PRIO_PROCESS, 0, RECORDER_NICE)
    except OSError:
        pass  # without the right (CAP_SYS_NICE), at the ordinary weight
    memory = shared_memory.SharedMemory(name=region_name, create=False)
    rings = rings_of(plan, memory.buf)
    recorder = sources = None
    try:
        sources = sources_of(plan, memory.buf)
        try:
            recorder = Recorder(plan, rings, time.monotonic_ns, sources)
        except LiveViewUnavailable as error:
            messages.send(("failed", str(error)))
            return
        messages.send(("started", (recorder.address, recorder.view_error)))
        while not orphaned.is_set():
            recorder.drain()
            if messages.poll(plan.drain_ns / 1e9):
                try:
                    message = messages.recv()
                except (EOFError, OSError):  # the parent is gone: finish what we have
                    orphaned.set()
                    break
                if message == "stop":
                    break  # its loops are done, the rings hold their last samples
                if message[0] == "event":  # ("event", kind, payload, time_ns)
                    recorder.event(*message[1:])
                    continue
                _, ring = message  # ("add", RecordedRing): a stream a live patch added
                recorder.add(ring, ring_of(ring, memory.buf))
        summary = recorder.finish()
        if not orphaned.is_set():
            messages.send(("finished", summary))
    finally:
        recorder = sources = None  # their views into the region go before it is closed
        for ring in rings.values():
            ring.close()
        rings = None
        memory.close()


class RecorderProcess:
    """The parent's handle on the recorder process."""

    STOP_TIMEOUT_S = 60.0  # the last drain and the summary of a long run take a while

    def __init__(self, plan: RecorderPlan, region_name: str):
        import multiprocessing

        context = multiprocessing.get_context("spawn")
        self.messages, theirs = context.Pipe(duplex=True)
        self.process = context.Process(target=record_main, args=(plan, region_name, os.getpid(), theirs),
                                       name="hapticop-recorder", daemon=True)
        self.process.start()
        theirs.close()
        self.plan = plan
        self.pid = self.process.pid
        self.address: str | None = None  # the live view's, once started
        self.view_error: str | None = None  # why the live view did not start (the recording goes on)

    def wait_started(self, timeout_s: float = 60.0) -> str | None:
        """Before the loops run: the recorder has the region mapped and the file open (None), or
        what went wrong. Starting takes a second or two (a new interpreter, numpy, mcap)."""
        try:
            if self.messages.poll(timeout_s):
                kind, value = self.messages.recv()
                if kind == "started":
                    self.address, self.view_error = value
                    return None
                if kind == "failed":
                    return f"{value}; the run goes on unrecorded and unseen"
        except (OSError, EOFError):
            pass
        return (f"the recorder (process {self.pid}) did not start within {timeout_s:g} s "
                f"(exit code {self.process.exitcode}); the run goes on unrecorded")

    def add(self, ring: RecordedRing) -> None:
        """Record a stream a live patch added (its ring lies in the region's spare room)."""
        try:
            self.messages.send(("add", ring))
        except (OSError, EOFError):
            pass  # the recorder is gone: the run says so when it stops it

    def event(self, kind: str, payload: dict, time_ns: int) -> None:
        """Something the run told its observer: recorded at the recorder's next look at its pipe."""
        try:
            self.messages.send(("event", kind, payload, time_ns))
        except (OSError, EOFError):
            pass  # the recorder is gone: the run says so when it stops it

    def stop(self) -> tuple[dict | None, str | None]:
        """Ask for the last drain and the finished file: (summary, None), or (None, what went wrong)."""
        try:
            self.messages.send("stop")
            deadline = time.monotonic() + self.STOP_TIMEOUT_S
            while time.monotonic() < deadline and self.messages.poll(max(0.0, deadline - time.monotonic())):
                kind, value = self.messages.recv()
                if kind == "finished":
                    return value, None
        except (OSError, EOFError):
            pass
        finally:
            self.process.join(timeout=5)
            if self.process.is_alive():
                self.process.kill()
                self.process.join(timeout=5)
        code = self.process.exitcode
        return None, (f"the recorder (process {self.pid}) ended with exit code {code} before finishing the "
                      f"recording; what it flushed is in {self.plan.path}.part: `hapticop recover` makes it a "
                      "valid file")


# -- under the virtual clock: drained by the main process -----------------------------------

class InlineRecorder:
    """The recorder in the main process, drained between two main-thread cycles whenever
    `DRAIN_INTERVAL_NS` of simulated time has passed: deterministic, so tests count exactly."""

    def __init__(self, plan: RecorderPlan, buffer, clock: Callable[[], int]):
        self.rings = rings_of(plan, buffer)
        self.buffer = buffer
        self.recorder = Recorder(plan, self.rings, clock, sources_of(plan, buffer))
        self.clock = clock
        self.drain_ns = plan.drain_ns
        self.next_ns = clock() + self.drain_ns
        self.address, self.view_error = self.recorder.address, self.recorder.view_error

    @staticmethod
    def wait_started() -> None:
        return None

    def add(self, ring: RecordedRing) -> None:
        """Record a stream a live patch added (its ring lies in the region's spare room)."""
        self.recorder.add(ring, ring_of(ring, self.buffer))

    def event(self, kind: str, payload: dict, time_ns: int) -> None:
        self.recorder.event(kind, payload, time_ns)

    def between_cycles(self) -> None:
        now = self.clock()
        if now >= self.next_ns:
            self.recorder.drain()
            self.next_ns = now + self.drain_ns

    def stop(self) -> tuple[dict | None, str | None]:
        try:
            return self.recorder.finish(), None
        finally:
            self.recorder = None  # the timing source's views into the region go with it
            for ring in self.rings.values():
                ring.close()
