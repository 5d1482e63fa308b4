"""Finding a block class from the `block:` name an activity gives.

Built-in blocks have short names. Any other block is named by its import path,
`package.module:ClassName`, so an application can bring its own blocks without touching
hapticop. Modules are imported only when a composition names them.
"""

from __future__ import annotations

import difflib
import importlib
import re

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
    "hallway_world": "hapticop.sim.world:HallwayWorld",
    "blind_operator": "hapticop.sim.blind_operator:Operator",
    "falcon_simulator": "hapticop.sim.devices.falcon:FalconSimulator",
    "tim561_simulator": "hapticop.sim.devices.tim561:Tim561Simulator",
    "ropod_plant": "hapticop.sim.devices.ropod_plant:RopodPlantSimulator",
    "counter": "hapticop.blocks.basic:Counter",
    "echo": "hapticop.blocks.basic:Echo",
}

_IMPORT_PATH = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_]\w*$")


class UnknownBlock(LookupError):
    def __init__(self, name: str, reason: str, hint: str = ""):
        super().__init__(reason)
        self.name, self.reason, self.hint = name, reason, hint


def resolve(name: str) -> type[Block]:
    """The block class for `name`, or `UnknownBlock` saying why not."""
    target = BUILTIN.get(name)
    if target is None:
        if not _IMPORT_PATH.match(name):
            close = difflib.get_close_matches(name, BUILTIN, n=1)
            hint = f"did you mean '{close[0]}'?" if close else "use a built-in name or 'package.module:ClassName'"
            raise UnknownBlock(name, f"unknown block type '{name}'", hint)
        target = name
    module_name, class_name = target.split(":")
    try:
        module = importlib.import_module(module_name)
    except ImportError as error:
        raise UnknownBlock(name, f"cannot import module '{module_name}' for block '{name}': {error}") from None
    cls = getattr(module, class_name, None)
    if not (isinstance(cls, type) and issubclass(cls, Block)):
        raise UnknownBlock(name, f"'{target}' is not a hapticop Block class")
    return cls
