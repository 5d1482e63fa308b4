"""One owner's Life Cycle State Machine, stepped once per cycle of its thread.

The owner (an activity or a thread) moves on its own through the deploying states
(creation, resource configuration) as its hooks complete; there it ignores coordination,
except a request to clean, which is always honoured so a shutdown is bounded. In the ready
states it follows the requests the mediator's flag maps send, and goes on to running by
itself when it starts `auto`. Every state is mirrored in the shared region (a state byte and
a level flag per state), every step of progress raises its event flag, and a hook that
raises leaves the owner in its state with a failure code until the mediator decides.
"""

from __future__ import annotations

import gc
import traceback
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hapticop.composition import lcsm
from hapticop.composition.lcsm import State
from hapticop.runtime.logs import Logger

# Failure codes in region.failed
OK, RESOURCE_FAILED, CAPABILITY_FAILED, RUNNING_FAILED, CLEANING_FAILED, CREATION_FAILED = range(6)
FAILURE_TEXT = {CREATION_FAILED: "creation failed", RESOURCE_FAILED: "resource configuration failed",
                CAPABILITY_FAILED: "capability configuration failed", RUNNING_FAILED: "running failed",
                CLEANING_FAILED: "cleaning failed"}


_STATES = tuple(State(value) for value in range(len(State)))  # by value, without an enum call per cycle
# A numpy integer compared with an IntEnum member goes through numpy's conversion of the member
# (about 14 us); the cycle path compares the state byte with plain ints.
_RUNNING = int(State.RUNNING)


def _succeeds(hook: Callable[[], object]) -> bool:
    return hook() is not False


@dataclass
class Hooks:
    create: Callable[[], object]
    configure_resources: Callable[[], object]
    configure_capabilities: Callable[[], object]
    compute: Callable[[], object]
    pausing: Callable[[], object]
    clean: Callable[[], object]


class Lifecycle:
    def __init__(self, flags: np.ndarray, states: np.ndarray, failed: np.ndarray, owner_index: int,
                 flag_index: dict[str, int], prefix: str, hooks: Hooks, start_on_request: bool, log: Logger,
                 reached: np.ndarray | None = None):
        self.flags, self.states, self.failed, self.index = flags, states, failed, owner_index
        self.reached = reached  # every state entered, as bits: did it ever run? (the run's exit status)
        self.hooks, self.on_request, self.log, self.prefix = hooks, start_on_request, log, prefix
        base = f"{prefix}.lcsm."
        self.state_flag = [flag_index[base + s.flag_name] for s in State]
        self.event = {name: flag_index[base + name] for name in lcsm.PROGRESS_FLAGS}
        self.request = {name: flag_index[base + name] for name in lcsm.REQUEST_FLAGS}
        # The requests a running owner answers, looked at first each step: none set is the steady state.
        self._running_requests = tuple(self.request[name] for name in (
            "request_cleaning", "request_resource_configuration", "request_capability_configuration",
            "request_pausing"))
        self.capabilities_ready = False
        self.resume_running = False
        self.created = False  # an owner never created has nothing to clean
        self.error: BaseException | None = None  # the last failure, for a harness that drives it by hand
        self.flags[self.state_flag[self.state]] = 1

    @property
    def state(self) -> State:
        return _STATES[self.states[self.index]]

    def _enter(self, new: State) -> None:
        old = self.state
        self.flags[self.state_flag[old]] = 0
        self.flags[self.state_flag[new]] = 1
        self.states[self.index] = new
        if self.reached is not None:
            self.reached[self.index] |= 1 << int(new)
        if new is State.CAPABILITY_CONFIGURATION:
            self.capabilities_ready = False
        elif new is State.RUNNING:
            # What is alive once an owner runs is the system's furniture: frozen, the garbage
            # collector never walks it again (a full collection of a process with numpy and
            # pydantic loaded stalls every thread for about 100 ms here).
            gc.freeze()
        self.log.info("lcsm %s -> %s", old.flag_name, new.flag_name)

    def _requested(self, name: str) -> bool:
        index = self.request[name]
        if self.flags[index]:
            self.flags[index] = 0
            return True
        return False

    def _raise(self, event: str) -> None:
        self.flags[self.event[event]] = 1

    def _fail(self, code: int, event: str | None, error: BaseException) -> None:
        self.failed[self.index] = code
        self.error = error
        if event:
            self._raise(event)
        self.log.error("%s: %s", FAILURE_TEXT[code], "".join(traceback.format_exception_only(error)).strip())

    def request_cleaning(self) -> None:
        """For the runtime's own shutdown path (no flag map asked)."""
        self.flags[self.request["request_cleaning"]] = 1

    def cleaning_requested(self) -> bool:
        return bool(self.flags[self.request["request_cleaning"]])

    def step(self) -> bool:
        """One step of the machine; True when it ran the running hook (compute)."""
        if self.states[self.index] == _RUNNING:  # the steady state, in one pass: no request, compute
            flags = self.flags
            a, b, c, d = self._running_requests
            if not (flags[a] or flags[b] or flags[c] or flags[d]):
                try:  # `_run`, written out: this is every running owner's every cycle
                    if self.hooks.compute() is True:
                        self._raise("running_complete")
                except Exception as error:  # noqa: BLE001
                    self.fail_running(error)
                return True
        state = self.state
        if state not in (State.CLEANING, State.DONE) and self._requested("request_cleaning"):
            self._enter(State.CLEANING)
            state = State.CLEANING
        if state is State.CREATION:
            self._create()
        elif state is State.RESOURCE_CONFIGURATION:
            self._configure_resources()
        elif state is State.CLEANING:
            self._clean()
        elif state is State.DONE:
            if self._requested("request_creation"):
                self.failed[self.index] = OK
                self._enter(State.CREATION)
        else:
            return self._ready(state)
        return False

    # -- deploying ------------------------------------------------------------------------
    def _create(self) -> None:
        if self.reached is not None:
            self.reached[self.index] |= 1 << State.CREATION  # stepped: its thread has started it
        if self.failed[self.index] == CREATION_FAILED:
            if not (self._requested("request_creation") or self._requested("request_resource_configuration")):
                return  # failed: wait for the mediator to ask for another attempt
            self.failed[self.index] = OK
        try:
            done = _succeeds(self.hooks.create)
        except Exception as error:  # noqa: BLE001 - any hook failure is reported, not fatal
            self._fail(CREATION_FAILED, "resource_configuration_failed", error)  # deploying failed
            return
        if done:
            self.created = True
            self._raise("creation_complete")
            self._enter(State.RESOURCE_CONFIGURATION)

    def _configure_resources(self) -> None:
        if self.failed[self.index] == RESOURCE_FAILED:
            if not self._requested("request_resource_configuration"):
                return  # failed: wait for the mediator to ask for another attempt
            self.failed[self.index] = OK
        try:
            done = _succeeds(self.hooks.configure_resources)
        except Exception as error:  # noqa: BLE001
            self._fail(RESOURCE_FAILED, "resource_configuration_failed", error)
            return
        if done:
            self._raise("resource_configuration_complete")
            self._enter(State.CAPABILITY_CONFIGURATION)

    # -- ready ----------------------------------------------------------------------------
    def _ready(self, state: State) -> bool:
        if self._requested("request_resource_configuration"):
            self.resume_running = self.resume_running or state is State.RUNNING
            self.failed[self.index] = OK
            self._enter(State.RESOURCE_CONFIGURATION)
            return False
        if self._requested("request_capability_configuration"):
            self.resume_running = self.resume_running or state is State.RUNNING
            self.failed[self.index] = OK
            self._enter(State.CAPABILITY_CONFIGURATION)
            state = State.CAPABILITY_CONFIGURATION
        if state is State.CAPABILITY_CONFIGURATION:
            self._configure_capabilities()
        elif state is State.RUNNING:
            if self._requested("request_pausing"):
                self._enter(State.PAUSING)
                return False
            if self._run(self.hooks.compute) is True:
                self._raise("running_complete")
            return True
        else:  # pausing
            if self._requested("request_running"):
                self.failed[self.index] = OK
                self._enter(State.RUNNING)
                return False
            try:
                self.hooks.pausing()
            except Exception as error:  # noqa: BLE001
                self._fail(RUNNING_FAILED, None, error)
        return False

    def flush(self, hook: Callable[[], object]) -> None:
        """A running owner's write phase, after its thread's schedule computed."""
        if self.states[self.index] == _RUNNING:
            self._run(hook)

    def _run(self, hook: Callable[[], object]) -> object:
        """A running hook (compute, flush): one that raises fails the owner into pausing."""
        try:
            return hook()
        except Exception as error:  # noqa: BLE001
            self.fail_running(error)
            return None

    @property
    def configured(self) -> bool:
        """Its hooks have built what they build: running, paused, or capabilities ready."""
        state = self.state
        return state in (State.RUNNING, State.PAUSING) or (
            state is State.CAPABILITY_CONFIGURATION and self.capabilities_ready)

    def fail_running(self, error: BaseException) -> None:
        """A running owner's hook raised: reported, and the owner pauses (safe outputs)."""
        self._fail(RUNNING_FAILED, None, error)
        if self.state is State.RUNNING:
            self._enter(State.PAUSING)

    def _configure_capabilities(self) -> None:
        if self.failed[self.index] == CAPABILITY_FAILED:
            return  # wait for a request to configure again
        if not self.capabilities_ready:
            try:
                self.capabilities_ready = _succeeds(self.hooks.configure_capabilities)
            except Exception as error:  # noqa: BLE001
                self._fail(CAPABILITY_FAILED, "capability_configuration_failed", error)
                return
            if not self.capabilities_ready:
                return
            self._raise("capability_configuration_complete")
        if self._requested("request_pausing"):
            self._enter(State.PAUSING)
        elif not self.on_request or self.resume_running or self._requested("request_running"):
            self.resume_running = False
            self._enter(State.RUNNING)

    # -- cleaning -------------------------------------------------------------------------
    def _clean(self) -> None:
        try:
            done = _succeeds(self.hooks.clean) if self.created else True
        except Exception as error:  # noqa: BLE001
            self._fail(CLEANING_FAILED, None, error)
            done = True  # nothing more can be done: it is over
        if done:
            self._raise("deletion_complete")
            self._enter(State.DONE)
