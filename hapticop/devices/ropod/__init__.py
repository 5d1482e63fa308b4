"""The ropod platform: smart-wheel process data, kinematics, the velocity controller and a simulator.

Pure numpy libraries with no hapticop runtime dependency; the ropod controller and EtherCAT
blocks build on them. Sources and conventions: docs/devices/ropod.md.
"""

from hapticop.devices.ropod.controller_params import (
    THESIS_PLATFORM_THETA,
    THESIS_PLATFORM_XY,
    THESIS_WHEEL,
    LinearControllerParams,
)
from hapticop.devices.ropod.geometry import Geometry
from hapticop.devices.ropod.kinematics import SmartWheelKinematics, distribute_qp, jacobian
from hapticop.devices.ropod.linear_bank import ControllerBank
from hapticop.devices.ropod.pdo import (
    RXPDO_BYTES,
    RXPDO_DTYPE,
    TXPDO_BYTES,
    TXPDO_DTYPE,
    Com1,
    Stat1,
    new_rx_image,
    new_tx_image,
    pdo_image,
    rxpdo_view,
    txpdo_view,
)
from hapticop.devices.ropod.plant import PlantParams, RopodPlant
from hapticop.devices.ropod.velocity_controller import (
    THESIS_PIVOT_OFFSETS_RAD,
    PlatformControllerParams,
    PlatformVelocityController,
)

__all__ = [
    "PlatformControllerParams", "PlatformVelocityController", "THESIS_PIVOT_OFFSETS_RAD",
    "ControllerBank", "LinearControllerParams", "THESIS_PLATFORM_XY", "THESIS_PLATFORM_THETA", "THESIS_WHEEL",
    "Geometry", "SmartWheelKinematics", "distribute_qp", "jacobian",
    "TXPDO_BYTES", "RXPDO_BYTES", "TXPDO_DTYPE", "RXPDO_DTYPE", "Stat1", "Com1",
    "txpdo_view", "rxpdo_view", "pdo_image", "new_tx_image", "new_rx_image",
    "PlantParams", "RopodPlant",
]
