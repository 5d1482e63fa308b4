"""Live changes mean what their reply says: whole or nothing, never after a refusal, never over
another change, never for a client that left, and answered at shutdown (runtime/live.py)."""

import threading
import time

from hapticop.control.address import ControlError
from hapticop.control.client import request
from hapticop.control.server import ControlServer
from hapticop.runtime.live import APPLIED, CANCELLED, FAILED, STALE, WAITING
from hapticop.testing import stepped_system
from hapticop.validation import validate_text
from hapticop.validation.patches import load_patch

from .control_helpers import PATIENCE_S

TEXT = """
version: 1
name: semantics
threads:
  main: {period: 1ms, deploy: main, schedules: {0: [mediator, gain, other]}}
activities:
  mediator: {block: mediator}
  gain: {block: "tests.blocks:Gain", params: {gain: 1.0}}
  other: {block: "tests.blocks:Gain", params: {gain: 10.0}}
patches:
  raise_other:
    at: 50ms
    patch: [{op: replace, path: /activities/other/params/gain, value: 11.0}]
"""

GAIN = "[{op: replace, path: /activities/gain/params/gain, value: %s}]"
ADD_UNBUILDABLE = """
- {op: replace, path: /activities/gain/params/gain, value: 2.0}
- {op: add, path: /activities/broken, value: {block: "tests.blocks:Unbuildable"}}
- {op: replace, path: /threads/main/schedules/0, value: [mediator, gain, other, broken]}
"""


class Stepped:
    """The composition on the virtual clock; the test is its main thread and steps it when it likes."""

    def __init__(self, system, threads):
        self.system, self.threads, self.now = system, threads, 0

    def cycles(self, count: int = 1) -> None:
        for _ in range(count):
            self.now += 1_000_000
            self.system.clock.advance_to(self.now)
            self.system._between_cycles()
            for thread in self.threads.values():
                thread.cycle()

    def params(self, activity: str):
        return self.system.runners[activity].block.params


def stepped(tmp_path):
    validated = validate_text(TEXT, "semantics.yaml")
    assert validated.report.ok, validated.report.diagnostics
    return stepped_system(validated, tmp_path)


def _patch(text: str):
    return load_patch(text, "patch.yaml")


def test_a_patch_whose_wait_ran_out_is_cancelled_and_never_applied_later(tmp_path):
    """The main thread stalls past the client's wait: the reply says not applied, and it never is."""
    with stepped(tmp_path) as (system, threads):
        run = Stepped(system, threads)
        run.cycles(3)
        pending = system.live.ask(_patch(GAIN % 5.0), "patch.yaml", lambda: True, timeout_s=0.2)
        assert pending.outcome == CANCELLED and "cycle boundary" in pending.error
        run.cycles(5)  # the main thread comes back: nothing queued may take effect now
        assert run.params("gain").gain == 1.0 and system.description.revision == 0


def test_a_patch_racing_its_deadline_is_reported_as_what_happened(tmp_path):
    """Patches whose waits run out while the main thread steps beside them: each reply is the truth,
    so the value in force is always the last one reported applied."""
    with stepped(tmp_path) as (system, threads):
        run = Stepped(system, threads)
        stop = threading.Event()

        def main_thread() -> None:
            while not stop.is_set():
                run.cycles()
                time.sleep(0.0005)

        stepping = threading.Thread(target=main_thread)
        stepping.start()
        outcomes = []
        try:
            for i in range(40):
                value = 100.0 + i
                # waits of 0 to 3 ms against a main thread that steps about every 1 ms: some land, some not
                pending = system.live.ask(_patch(GAIN % value), "patch.yaml", lambda: True, timeout_s=(i % 4) / 1000)
                outcomes.append((value, pending.outcome))
                applied = [v for v, outcome in outcomes if outcome == APPLIED]
                deadline = time.monotonic() + PATIENCE_S
                while system.runners["gain"].retuned is not None and time.monotonic() < deadline:
                    time.sleep(0.001)  # the block takes its parameters before its next step
                assert system.description.activities["gain"].params.gain == (applied[-1] if applied else 1.0)
        finally:
            stop.set()
            stepping.join()
        kinds = {outcome for _, outcome in outcomes}
        assert kinds <= {APPLIED, CANCELLED}, outcomes
        assert run.params("gain").gain == system.description.activities["gain"].params.gain


def test_a_patch_whose_added_block_cannot_be_built_changes_nothing(tmp_path):
    """A retune and an addition in one patch: the addition fails, so the retune is not applied either."""
    with stepped(tmp_path) as (system, threads):
        run = Stepped(system, threads)
        run.cycles(3)
        activities = list(system.layout.activities)
        result = {}
        asking = threading.Thread(target=lambda: result.update(pending=system.live.ask(
            _patch(ADD_UNBUILDABLE), "patch.yaml", lambda: True, timeout_s=PATIENCE_S)))
        asking.start()
        deadline = time.monotonic() + PATIENCE_S
        while asking.is_alive() and time.monotonic() < deadline:
            run.cycles()
            time.sleep(0.001)
        asking.join()
        pending = result["pending"]
        assert pending.outcome == FAILED and "the device is not there" in pending.error
        run.cycles(3)
        assert run.params("gain").gain == 1.0 and system.runners["gain"].retuned is None
        assert "broken" not in system.runners and system.layout.activities == activities
        assert system.description.revision == 0 and "broken" not in system.composition.activities
        # the room it took is given back: the same addition, buildable this time, fits and runs
        fixed = ADD_UNBUILDABLE.replace("tests.blocks:Unbuildable", "tests.blocks:Gain")
        asking = threading.Thread(target=lambda: result.update(pending=system.live.ask(
            _patch(fixed), "patch.yaml", lambda: True, timeout_s=PATIENCE_S)))
        asking.start()
        while asking.is_alive():
            run.cycles()
            time.sleep(0.001)
        asking.join()
        assert result["pending"].outcome == APPLIED
        run.cycles(3)
        assert run.params("gain").gain == 2.0 and "broken" in system.runners


def test_a_live_patch_prepared_before_a_scripted_one_landed_does_not_undo_it(tmp_path):
    """Compare-and-swap on the description: the live patch lands on what the scripted one left."""
    with stepped(tmp_path) as (system, threads):
        run = Stepped(system, threads)
        run.cycles(3)
        early = system.live.prepare(_patch(GAIN % 3.0), "patch.yaml")  # prepared before 50 ms
        run.cycles(60)  # the scripted patch raises 'other' to 11
        assert run.params("other").gain == 11.0
        system.live.pending.append(early)
        run.cycles(2)
        assert early.outcome == STALE
        assert system.description.activities["other"].params.gain == 11.0 and run.params("gain").gain == 1.0
        # asked through the control path, it is prepared again on the description as it is now
        result = {}
        asking = threading.Thread(target=lambda: result.update(pending=system.live.ask(
            _patch(GAIN % 3.0), "patch.yaml", lambda: True, timeout_s=PATIENCE_S)))
        asking.start()
        while asking.is_alive():
            run.cycles()
            time.sleep(0.001)
        asking.join()
        run.cycles(2)
        assert result["pending"].outcome == APPLIED
        assert run.params("gain").gain == 3.0 and run.params("other").gain == 11.0


def test_a_dry_run_says_per_activity_whether_it_is_retuned_or_reconfigured(tmp_path):
    with stepped(tmp_path) as (system, threads):
        Stepped(system, threads).cycles(10)
        patch = ("[{op: replace, path: /activities/gain/params/gain, value: 2.0},"
                 " {op: add, path: /activities/other/params/label, value: right}]")
        reply = system.service.handle({"op": "patch", "text": patch, "dry_run": True})
        assert reply["ok"] and reply["applied"] is False, reply
        assert "activity 'gain': retuned in place (gain)" in reply["changes"]
        assert ("activity 'other': reconfigured: stops and restarts other (resource configuration, for label)"
                in reply["changes"])


def test_status_shows_the_parameters_each_activity_runs_with_and_the_revision(tmp_path):
    with stepped(tmp_path) as (system, threads):
        run = Stepped(system, threads)
        run.cycles(60)
        status = system.service.status()
        assert status["revision"] == 1  # the scripted patch
        assert status["activities"]["other"]["params"] == {"gain": 11.0, "label": ""}
        assert status["activities"]["gain"]["params"]["gain"] == 1.0


def _serve(system, tmp_path):
    return ControlServer(tmp_path / "semantics.sock", system.service.handle)


def test_nothing_is_applied_for_a_client_that_left(tmp_path):
    """The client gives up while the main thread is stalled: its patch is withdrawn at once, so
    the main thread, when it comes back, applies nothing on its behalf."""
    with stepped(tmp_path) as (system, threads), _serve(system, tmp_path) as server:
        system.service.server = server
        run = Stepped(system, threads)
        run.cycles(3)
        try:
            request(server.path, {"op": "patch", "text": GAIN % 7.0}, timeout=0.3)
        except ControlError as error:
            assert "did not answer" in str(error)
        else:
            raise AssertionError("the client was answered although the main thread stood still")
        deadline = time.monotonic() + PATIENCE_S
        while (system.live.pending and system.live.pending[0].outcome == WAITING
               and time.monotonic() < deadline):
            time.sleep(0.01)
        withdrawn = system.live.pending[0]
        assert withdrawn.outcome == CANCELLED and "client left" in withdrawn.error, withdrawn.error
        run.cycles(5)
        assert run.params("gain").gain == 1.0 and system.description.revision == 0


def test_a_patch_waiting_at_shutdown_is_answered_and_never_applied(tmp_path):
    with stepped(tmp_path) as (system, threads), _serve(system, tmp_path) as server:
        system.service.server = server
        run = Stepped(system, threads)
        run.cycles(3)
        replies = []
        asking = threading.Thread(target=lambda: replies.append(
            request(server.path, {"op": "patch", "text": GAIN % 9.0}, timeout=PATIENCE_S)))
        asking.start()
        deadline = time.monotonic() + PATIENCE_S
        while not system.live.pending and time.monotonic() < deadline:
            time.sleep(0.005)
        system.live.close("the system is shutting down")  # as System.run does before the server stops
        server.stop()
        asking.join(PATIENCE_S)
        assert replies and replies[0]["ok"] is False and replies[0]["applied"] is False, replies
        assert "shutting down" in replies[0]["error"]
        run.cycles(3)
        assert run.params("gain").gain == 1.0
