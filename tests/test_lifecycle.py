"""The LCSM on its own: transitions, requests, failures, with a plain flags array."""

import numpy as np
import pytest

from hapticop.composition import lcsm
from hapticop.composition.lcsm import State
from hapticop.runtime.lifecycle import (
    CAPABILITY_FAILED,
    CREATION_FAILED,
    OK,
    RESOURCE_FAILED,
    RUNNING_FAILED,
    Hooks,
    Lifecycle,
)
from hapticop.runtime.logs import Level, Logger


class Recorder:
    """Hooks that record calls and can be told to wait or fail."""

    def __init__(self):
        self.calls = []
        self.wait = {}  # hook -> number of cycles to return False
        self.fail = set()

    def hook(self, name):
        def call():
            self.calls.append(name)
            if name in self.fail:
                raise RuntimeError(f"{name} broke")
            if self.wait.get(name, 0) > 0:
                self.wait[name] -= 1
                return False
            return None
        return call

    def hooks(self):
        return Hooks(*(self.hook(n) for n in ("create", "configure_resources", "configure_capabilities",
                                              "compute", "pausing", "clean")))


class Machine:
    def __init__(self, on_request=False):
        names = [f"a.lcsm.{n}" for n in lcsm.STATE_FLAGS + lcsm.PROGRESS_FLAGS + lcsm.REQUEST_FLAGS]
        self.index = {n: i for i, n in enumerate(names)}
        self.flags = np.zeros(len(names), np.uint8)
        self.states = np.zeros(1, np.uint8)
        self.failed = np.zeros(1, np.uint8)
        self.rec = Recorder()
        import queue
        self.log_queue = queue.SimpleQueue()
        log = Logger("a", Level.DEBUG, self.log_queue, lambda: 0)
        self.m = Lifecycle(self.flags, self.states, self.failed, 0, self.index, "a", self.rec.hooks(), on_request, log)

    def flag(self, name):
        return bool(self.flags[self.index[f"a.lcsm.{name}"]])

    def request(self, name):
        self.flags[self.index[f"a.lcsm.request_{name}"]] = 1

    def steps(self, n=1):
        for _ in range(n):
            self.m.step()
        return self.m.state


def test_auto_start_walks_to_running_and_mirrors_state_flags():
    m = Machine()
    assert m.flag("creation") and m.steps(1) is State.RESOURCE_CONFIGURATION
    assert m.steps(2) is State.RUNNING
    assert [m.flag(s.flag_name) for s in State] == [s is State.RUNNING for s in State]
    for event in ("creation_complete", "resource_configuration_complete", "capability_configuration_complete"):
        assert m.flag(event)
    m.steps(3)
    assert m.rec.calls.count("compute") == 3


def test_configuration_hooks_may_wait():
    m = Machine()
    m.rec.wait["configure_resources"] = 5
    assert m.steps(6) is State.RESOURCE_CONFIGURATION
    assert m.steps(1) is State.CAPABILITY_CONFIGURATION


def test_on_request_waits_in_capability_configuration():
    m = Machine(on_request=True)
    assert m.steps(10) is State.CAPABILITY_CONFIGURATION and "compute" not in m.rec.calls
    m.request("running")
    assert m.steps(1) is State.RUNNING and not m.flag("request_running")  # consumed


def test_deploying_ignores_requests_but_keeps_them_pending():
    m = Machine(on_request=True)
    m.request("running")
    assert m.steps(1) is State.RESOURCE_CONFIGURATION and m.flag("request_running")
    assert m.steps(2) is State.RUNNING


def test_pause_resume_and_reconfigure_return_to_running():
    m = Machine()
    m.steps(3)
    m.request("pausing")
    assert m.steps(2) is State.PAUSING and "pausing" in m.rec.calls
    m.request("running")
    assert m.steps(1) is State.RUNNING
    m.request("resource_configuration")
    assert m.steps(1) is State.RESOURCE_CONFIGURATION
    assert m.steps(2) is State.RUNNING  # it was running, so it resumes
    m.request("capability_configuration")
    assert m.steps(1) is State.RUNNING and m.rec.calls.count("configure_capabilities") == 3


@pytest.mark.parametrize("hook, code, stays, event", [
    ("create", CREATION_FAILED, State.CREATION, "resource_configuration_failed"),
    ("configure_resources", RESOURCE_FAILED, State.RESOURCE_CONFIGURATION, "resource_configuration_failed"),
    ("configure_capabilities", CAPABILITY_FAILED, State.CAPABILITY_CONFIGURATION, "capability_configuration_failed"),
])
def test_a_failing_hook_is_reported_and_waits_for_the_mediator(hook, code, stays, event):
    m = Machine()
    m.rec.fail.add(hook)
    assert m.steps(5) is stays
    assert m.failed[0] == code and m.flag(event)
    assert m.rec.calls.count(hook) == 1  # not retried on its own
    m.rec.fail.clear()
    m.request("resource_configuration" if hook != "configure_capabilities" else "capability_configuration")
    assert m.steps(4) is State.RUNNING and m.failed[0] == OK


def test_failing_compute_pauses_until_asked_to_run():
    m = Machine()
    m.steps(3)
    m.rec.fail.add("compute")
    assert m.steps(1) is State.PAUSING and m.failed[0] == RUNNING_FAILED
    m.rec.fail.clear()
    m.request("running")
    assert m.steps(1) is State.RUNNING and m.failed[0] == OK


@pytest.mark.parametrize("steps", [0, 1, 2, 3])
def test_cleaning_is_honoured_from_every_state(steps):
    m = Machine()
    m.rec.wait["configure_resources"] = 100  # stuck in resource configuration after 1 step
    m.steps(steps)
    m.request("cleaning")
    assert m.steps(1) is State.DONE and m.flag("deletion_complete")
    assert ("clean" in m.rec.calls) == (steps >= 1)  # never created: nothing to clean


def test_done_is_inert_until_revived():
    m = Machine()
    m.steps(3)
    m.request("cleaning")
    m.steps(1)
    calls = len(m.rec.calls)
    assert m.steps(5) is State.DONE and len(m.rec.calls) == calls
    m.request("creation")
    assert m.steps(1) is State.CREATION and m.steps(3) is State.RUNNING
