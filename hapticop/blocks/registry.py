"""Finding a block class from the `block:` name an activity gives.

Built-in blocks have short names. Any other block is named by its import path,
`package.module:ClassName`, so an application can bring its own blocks without touching
hapticop; an installed package may also give its blocks short names through the
`hapticop.blocks` entry-point group (`spring = "mypkg.blocks:Spring"`); a module beside the
composition file is found too (`search_beside`). Modules are imported
only when a composition names them, and not at all while `blocks_not_imported()` is in
effect: checking an untrusted file must not run its code.

A composition read from a recording is data: within `blocks_of_a_recording(trusted=False)`
only built-in names resolve, and every other name is refused without looking for its module;
with `trusted=True` (the user said so for that file) modules are imported from installed
packages and PYTHONPATH, never from the recording's folder nor, implicitly, the current one.
"""

from __future__ import annotations

import contextlib
import difflib
import functools
import importlib
import importlib.machinery
import importlib.metadata
import importlib.util
import os
import re
import sys
from collections.abc import Iterator
from contextvars import ContextVar
from pathlib import Path

from hapticop.blocks.base import Block

BUILTIN: dict[str, str] = {
    "mediator": "hapticop.blocks.mediator:ApplicationMediator",
    "falcon": "hapticop.blocks.falcon:Falcon",
    "lidar": "hapticop.blocks.lidar:Lidar",
    "ethercat_master": "hapticop.blocks.ethercat:EthercatMaster",
    "ethercat_watchdog": "hapticop.blocks.ethercat:EthercatWatchdog",
    "ropod_controller": "hapticop.blocks.ropod:RopodController",
    "ropod_truth": "hapticop.blocks.ropod_truth:RopodTruth",
    "haptic_controller": "hapticop.blocks.haptic:HapticController",
    "scan_field": "hapticop.blocks.scan_field:ScanFieldBlock",
    "shared_control": "hapticop.blocks.shared:SharedControl",
    "virtual_wall": "hapticop.blocks.effects:VirtualWall",
    "spring_damper": "hapticop.blocks.effects:SpringDamper",
    "viscous_field": "hapticop.blocks.effects:ViscousField",
    "workspace_limit": "hapticop.blocks.effects:WorkspaceLimit",
    "coupling": "hapticop.blocks.coupling:Coupling",
    "contact_to_handle": "hapticop.blocks.coupling:ContactToHandle",
    "force_sum": "hapticop.blocks.forces:ForceSum",
    "force_limit": "hapticop.blocks.forces:ForceLimit",
    "button": "hapticop.blocks.button:Button",
    "link": "hapticop.blocks.link:Link",
    "round_trip": "hapticop.blocks.round_trip:RoundTrip",
    "pose_predictor": "hapticop.blocks.prediction:PosePredictor",
    "energy_tank": "hapticop.blocks.tank:EnergyTankBlock",
    "speed_governor": "hapticop.blocks.governor:SpeedGovernor",
    "scene_world": "hapticop.sim.scene_world:SceneWorld",
    "blind_operator": "hapticop.sim.blind_operator:Operator",
    "scripted_hand": "hapticop.sim.scripted_hand:ScriptedHand",
    "falcon_simulator": "hapticop.sim.devices.falcon:FalconSimulator",
    "tim561_simulator": "hapticop.sim.devices.tim561:Tim561Simulator",
    "ropod_plant": "hapticop.sim.devices.ropod_plant:RopodPlantSimulator",
    "recorded_source": "hapticop.observe.recorded_source:RecordedSource",
    "counter": "hapticop.blocks.basic:Counter",
    "echo": "hapticop.blocks.basic:Echo",
    "zenoh_bridge": "hapticop.blocks.bridge:ZenohBridge",
    "ros2_bridge": "hapticop.blocks.ros2_bridge:Ros2Bridge",
}

RETIRED: dict[str, str] = {
    "hallway_world": "the hallways are scene files now: use 'block: scene_world' with 'scene: H1' (or 'hallway: H1'); "
                     "its other parameters are the same",
}
"""Built-in names no longer built in, and what to write instead."""

_IMPORT_PATH = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_]\w*$")


_importing = ContextVar("importing_blocks", default=True)
_untrusted = ContextVar("untrusted_blocks", default=False)  # only built-in names resolve
_not_from: ContextVar[tuple[str, ...]] = ContextVar("blocks_not_from", default=())  # folders never imported from


@contextlib.contextmanager
def blocks_not_imported() -> Iterator[None]:
    """Within this block, `resolve` finds third-party modules without importing them."""
    token = _importing.set(False)
    try:
        yield
    finally:
        _importing.reset(token)


@contextlib.contextmanager
def blocks_of_a_recording(trusted: bool, folder: str | Path) -> Iterator[None]:
    """Within this block, `resolve` reads a recording's composition as data: built-in names only,
    unless `trusted`; then never a module from `folder` (the recording's) nor the current directory
    unless PYTHONPATH names it."""
    explicit = {str(Path(p).resolve()) for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p}
    implicit = {"", ".", str(Path.cwd().resolve())} - explicit
    barred = (*implicit, str(Path(folder).resolve()))
    tokens = _untrusted.set(not trusted), _not_from.set(barred)
    try:
        yield
    finally:
        _untrusted.reset(tokens[0])
        _not_from.reset(tokens[1])


@contextlib.contextmanager
def _path_without(folders: tuple[str, ...]) -> Iterator[None]:
    """`sys.path` without these folders while a module is imported (the importer reads it then)."""
    if not folders:
        yield
        return
    kept = sys.path[:]
    sys.path[:] = [p for p in kept if p not in folders and str(Path(p or ".").resolve()) not in folders]
    importlib.invalidate_caches()
    try:
        yield
    finally:
        sys.path[:] = kept


class UnknownBlock(LookupError):
    def __init__(self, name: str, reason: str, hint: str = ""):
        super().__init__(reason)
        self.name, self.reason, self.hint = name, reason, hint


BESIDE_ENV = "HAPTICOP_BESIDE"  # the folders of the compositions loaded, newest first (children inherit it)


def search_beside(composition_file: str | Path) -> None:
    """Let `module:Class` blocks be found in the composition's own folder, as an author expects of
    a file kept beside the YAML that names it. Searched last, so it never hides an installed module;
    child processes inherit the search path. The folder is also the first of `beside_folders()`,
    where the files a composition names (a scene) are looked for at run time, as validation did."""
    folder = str(Path(composition_file).resolve().parent)
    if folder not in sys.path:
        sys.path.append(folder)
    os.environ[BESIDE_ENV] = os.pathsep.join([folder, *(f for f in beside_folders() if f != folder)])


def beside_folders() -> list[str]:
    """The folders of the compositions this process (or its parent) loaded, the newest first."""
    return [f for f in os.environ.get(BESIDE_ENV, "").split(os.pathsep) if f]


@functools.cache
def installed() -> dict[str, str]:
    """Short names that installed packages give their blocks (entry points), without importing them;
    read once per process (installing a package means starting hapticop again)."""
    found = {}
    for point in importlib.metadata.entry_points(group="hapticop.blocks"):
        if _IMPORT_PATH.match(point.value):
            found[point.name] = point.value
    return found


def resolve(name: str) -> type[Block] | None:
    """The block class for `name`, or `UnknownBlock` saying why not.

    None when `name` is a third-party block whose module exists but, under
    `blocks_not_imported()`, was not imported.
    """
    target = BUILTIN.get(name)
    if name in RETIRED:
        raise UnknownBlock(name, f"block '{name}' is no longer built in", RETIRED[name])
    if target is None and _untrusted.get():
        raise UnknownBlock(name, f"block '{name}' is not built in, and a recording's composition imports no module "
                                 "unless told to", "if you trust this file and the module it names, say so with "
                                 "--trust-blocks (installed packages and PYTHONPATH only)")
    if target is None and not _IMPORT_PATH.match(name):
        target = installed().get(name)
    if target is None:
        if not _IMPORT_PATH.match(name):
            close = difflib.get_close_matches(name, [*BUILTIN, *installed()], n=1)
            hint = f"did you mean '{close[0]}'?" if close else "use a built-in name or 'package.module:ClassName'"
            raise UnknownBlock(name, f"unknown block type '{name}'", hint)
        target = name
    module_name, class_name = target.split(":")
    own = module_name == "hapticop" or module_name.startswith("hapticop.")
    if not own and not _importing.get():
        if not _module_exists(module_name):
            raise UnknownBlock(name, f"cannot find module '{module_name}' for block '{name}'",
                               _where_python_looks(module_name))
        return None
    try:
        with _path_without(() if own else _not_from.get()):
            module = importlib.import_module(module_name)
    except ImportError as error:
        missing = getattr(error, "name", None)
        hint = (_where_python_looks(module_name) if missing and module_name.startswith(missing)
                else f"'{module_name}' was found, but importing it failed: install what it imports")
        raise UnknownBlock(name, f"cannot import module '{module_name}' for block '{name}': {error}", hint) from None
    cls = getattr(module, class_name, None)
    if not (isinstance(cls, type) and issubclass(cls, Block)):
        raise UnknownBlock(name, f"'{target}' is not a hapticop Block class")
    return cls


def _where_python_looks(module_name: str) -> str:
    """How a `module:Class` block is found, for a module that was not."""
    return (f"Python looks for '{module_name.replace('.', '/')}.py' (or a package of that name) beside the "
            "composition file, in the folders on PYTHONPATH, and among installed packages; an installed "
            "package may also give its blocks short names through the 'hapticop.blocks' entry point")


def _module_exists(module_name: str) -> bool:
    """Whether `module_name` can be found, without running it or any of its parent packages.

    `importlib.util.find_spec` on a dotted name imports the parents, so each part below the
    top level is looked up in its parent's directories instead.
    """
    top, *rest = module_name.split(".")
    try:
        spec = importlib.util.find_spec(top)
        for part in rest:
            if spec is None or spec.submodule_search_locations is None:
                return False
            spec = importlib.machinery.PathFinder.find_spec(part, list(spec.submodule_search_locations))
    except (ImportError, ValueError):
        return False
    return spec is not None
