"""What a running system answers on its control socket (`control.py`): its status, and patches."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from hapticop.blocks.interface import Params
from hapticop.composition.lcsm import State
from hapticop.composition.placement import BRIDGE, HEALTH, LINK_FIGURES, link_stream
from hapticop.control.address import ControlError, is_system_name, socket_path
from hapticop.control.server import ControlServer
from hapticop.coordination.coordinator import Coordinator
from hapticop.rundirs import private_directory
from hapticop.runtime.clock import RealtimeClock, VirtualClock
from hapticop.runtime.described import Description
from hapticop.runtime.lifecycle import OK
from hapticop.runtime.live import APPLIED, APPLYING, LiveChanges
from hapticop.runtime.logs import Logger
from hapticop.runtime.region import Region
from hapticop.runtime.report import timing
from hapticop.runtime.streams import LatestSlot
from hapticop.runtime.supervisor import SECOND, failure
from hapticop.runtime.transport import writer_port
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
                 coordinator: Coordinator, description: Callable[[], Description], log: Logger,
                 attach: Callable[[], dict] | None = None,
                 params: Callable[[], dict[str, Params]] | None = None):
        self.name, self.live, self.region, self.clock = name, live, region, clock
        self.attach = attach  # what `hapticop view` needs to read the region from outside (viewer.Attachment)
        self.coordinator, self.description, self.log = coordinator, description, log  # description(): the running one
        self.params = params  # each activity's parameters as it runs them (modes over its description)
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
        if op == "attach" and self.attach is not None:
            return {"ok": True, "attach": self.attach()}
        if op != "patch":
            return {"ok": False, "error": f"unknown request {op!r}; expected 'status', 'attach' or 'patch'"}
        if wrong := _wrong_field(request):
            return {"ok": False, "error": f"malformed request: {wrong}"}
        file = request.get("file", "<patch>")
        try:
            patch = load_patch(request["text"], file)
            if request.get("dry_run"):
                pending = self.live.prepare(patch, file)
            else:
                present = self.server.client_present if self.server is not None else _always
                pending = self.live.ask(patch, file, present, APPLY_TIMEOUT_S)
        except PatchError as error:
            return {"ok": False, "error": "patch refused", "diagnostics": [d.to_json() for d in error.diagnostics]}
        result = {"ok": True, "diff": pending.diff, "changes": pending.changes(), "revision": pending.base.revision}
        if request.get("dry_run"):
            return {**result, "applied": False}
        if pending.outcome == APPLIED:
            return {**result, "applied": True, "revision": pending.base.revision + 1}
        if pending.outcome == APPLYING:  # taken by the main thread, still not finished: say so, not a guess
            return {"ok": False, "applied": None, "error": "the patch is being applied and has not finished; "
                    "`hapticop status` shows the revision once it has"}
        return {"ok": False, "applied": False, "error": f"patch not applied: {pending.error}"}

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
        description = self.description()
        composition = description.composition
        running = self.params() if self.params is not None else {}
        params = {a: (running.get(a) or resolved.params).model_dump(mode="json")
                  for a, resolved in description.activities.items()}
        return {
            "name": self.name,
            "clock": "virtual" if isinstance(clock, VirtualClock) else "realtime",
            "uptime_s": (clock.now_ns() - int(region.system[Region.STARTED_NS])) / SECOND,
            "threads": {t: {**owners[f"threads.{t}"], "schedule": int(region.selected[i])}
                        for t, i in layout.thread_index.items()},
            "revision": description.revision,
            "activities": {a: {**owners[a], "waiting_for": self._waiting(a, owners[a]["state"]),
                               "params": params.get(a)}
                           for a in layout.activity_index},
            "flags": sorted(name for name, i in layout.flag_index.items() if region.flags[i]),
            "markings": self.coordinator.markings(),
            "modes": [name for name, mode in composition.modes.items()
                      if mode.when in layout.flag_index and region.flag(mode.when)],
            "timing": timing(region, composition),
            "links": self._links(description, params),
        }

    def _links(self, description: Description, params: dict[str, dict]) -> dict:
        """The host's network bridge's link (docs/teleop.md), from the newest sample of each of its figures'
        streams in the region: nothing while the composition has no bridge, no figures before its first."""
        if BRIDGE not in params or link_stream(LINK_FIGURES[0]) not in self.region.layout.transports:
            return {}
        link: dict = {"peers": params[BRIDGE].get("peers", []), "health": HEALTH[0]}
        for figure in LINK_FIGURES:
            value = self._newest(description, link_stream(figure))
            if value is None:
                return link
            if figure == "health":
                link["health"] = HEALTH[int(value)] if 0 <= value < len(HEALTH) else str(value)
            elif figure in ("rtt", "jitter", "offset", "offset_error"):  # seconds on the stream, ms here
                link[f"{figure}_ms"] = value * 1e3 if math.isfinite(value) else None
            else:
                link[figure] = value
        return {BRIDGE: link}

    def _newest(self, description: Description, stream: str) -> float | None:
        """A scalar stream's newest sample, read from its latest slot, or None before its first."""
        spec = description.composition.streams.get(stream)
        transports = self.region.layout.transports.get(stream, [])
        if spec is None or not transports or transports[0].kind != "latest":
            return None
        port = writer_port(description.activities, spec)
        slot = LatestSlot(self.region.buffer_at(transports[0].offset, transports[0].nbytes), port)
        value, meta = np.zeros(port.shape, port.dtype), np.zeros(2, np.int64)
        try:
            return value.item() if slot.read_into(value, meta) else None
        finally:
            slot.close()


def _always() -> bool:
    return True


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
