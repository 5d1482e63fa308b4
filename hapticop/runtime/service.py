"""What a running system answers on its control socket (`control.py`): its status, and patches."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from hapticop.composition.description import Composition
from hapticop.composition.lcsm import State
from hapticop.coordination.coordinator import Coordinator
from hapticop.runtime.clock import RealtimeClock, VirtualClock
from hapticop.runtime.control import ControlError, ControlServer, is_system_name, socket_path
from hapticop.runtime.lifecycle import OK
from hapticop.runtime.live import LiveChanges
from hapticop.runtime.logs import Logger
from hapticop.runtime.region import Region
from hapticop.runtime.report import timing
from hapticop.runtime.rundirs import private_directory
from hapticop.runtime.supervisor import SECOND, failure
from hapticop.validation.patches import PatchError, load_patch

APPLY_TIMEOUT_S = 5.0  # a patch waits this long for the main thread's next cycle boundary


def control_path(socket: str | None, system: str) -> Path:
    """Where a system's socket goes (`socket`: a name or a path; default: the system's name),
    decided before the run makes anything. The default directory is made the way run
    directories are: the user's alone; another user's directory or a planted link there stops
    the run (`RunDirectoryError`), as does a name that is none (`ControlError`). A path the user
    gave is checked when the server starts."""
    name = socket or system
    path = socket_path(name)
    if is_system_name(name):
        private_directory(path.parent, option="--control PATH")
    return path


class ControlService:
    """Requests are handled on the control server's thread; patches are only prepared there
    and handed to the main thread through `live.pending`."""

    def __init__(self, name: str, live: LiveChanges, region: Region, clock: RealtimeClock | VirtualClock,
                 coordinator: Coordinator, composition: Callable[[], Composition], log: Logger):
        self.name, self.live, self.region, self.clock = name, live, region, clock
        self.coordinator, self.composition, self.log = coordinator, composition, log  # composition(): the running one
        self.server: ControlServer | None = None

    def start(self, path: Path) -> None:
        """Listen at `path` (from `control_path`), or warn and run on."""
        try:
            self.server = ControlServer(path, self.handle).start()
            self.log.info("control socket %s", self.server.path)
        except (ControlError, OSError) as error:
            self.log.warning("no control socket, so no live patches: %s", error)

    def stop(self) -> None:
        if self.server is not None:
            self.server.stop()

    def handle(self, request: dict) -> dict:
        """A request on the control socket (its own thread): status, or a patch."""
        op = request.get("op")
        if op == "status":
            return {"ok": True, "status": self.status()}
        if op != "patch":
            return {"ok": False, "error": f"unknown request {op!r}; expected 'status' or 'patch'"}
        if wrong := _wrong_field(request):
            return {"ok": False, "error": f"malformed request: {wrong}"}
        file = request.get("file", "<patch>")
        try:
            patch = load_patch(request["text"], file)
            pending = self.live.prepare(patch, file)
        except PatchError as error:
            return {"ok": False, "error": "patch refused", "diagnostics": [d.to_json() for d in error.diagnostics]}
        result = {"ok": True, "diff": pending.diff, "changes": pending.plan.describe()}
        if request.get("dry_run"):
            return {**result, "applied": False}
        self.live.pending.append(pending)
        if not pending.applied.wait(timeout=APPLY_TIMEOUT_S):
            return {"ok": False, "error": "the main thread did not reach a cycle boundary within 5 s"}
        if pending.error:
            return {"ok": False, "error": f"patch not applied: {pending.error}"}
        return {**result, "applied": True}

    def _waiting(self, activity: str, state: str) -> str | None:
        """What a configuring activity waits for; nothing once it left configuration."""
        configuring = state in (State.CREATION.flag_name, State.RESOURCE_CONFIGURATION.flag_name,
                                State.CAPABILITY_CONFIGURATION.flag_name)
        return self.region.waiting_for(activity) if configuring else None

    def status(self) -> dict:
        region, layout, clock = self.region, self.region.layout, self.clock
        owners = {owner: {"state": region.state_of(owner).flag_name,
                          "failed": failure(region, owner) if region.failed[i] != OK else None}
                  for owner, i in layout.owner_index.items()}
        composition = self.composition()
        return {
            "name": self.name,
            "clock": "virtual" if isinstance(clock, VirtualClock) else "realtime",
            "uptime_s": (clock.now_ns() - int(region.system[Region.STARTED_NS])) / SECOND,
            "threads": {t: {**owners[f"threads.{t}"], "schedule": int(region.selected[i])}
                        for t, i in layout.thread_index.items()},
            "activities": {a: {**owners[a], "waiting_for": self._waiting(a, owners[a]["state"])}
                           for a in layout.activity_index},
            "flags": sorted(name for name, i in layout.flag_index.items() if region.flags[i]),
            "markings": self.coordinator.markings(),
            "modes": [name for name, mode in composition.modes.items()
                      if mode.when in layout.flag_index and region.flag(mode.when)],
            "timing": timing(region, composition),
        }


PATCH_FIELDS = {"text": (str, "the patch's text"), "file": (str, "a file name"), "dry_run": (bool, "true or false")}


def _wrong_field(request: dict) -> str | None:
    """What is wrong with a patch request's fields, or None: a field of the wrong type is refused, not
    guessed at (a `dry_run` of "no" or 0 must not decide whether a running system changes)."""
    if "text" not in request:
        return "a patch request needs 'text', the patch"
    for name, (kind, what) in PATCH_FIELDS.items():
        if name in request and not isinstance(request[name], kind):
            return f"'{name}' must be {what}, not {_json_type(request[name])}"
    return None


def _json_type(value: object) -> str:
    names = {bool: "a boolean", int: "a number", float: "a number", str: "a string", list: "an array",
             dict: "an object", type(None): "null"}
    return names.get(type(value), type(value).__name__)
