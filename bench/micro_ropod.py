"""Hand micro-benchmark (not a test): microseconds per controller cycle and per simulator step.

    python bench/micro_ropod.py [cycles]

Runs controller and plant in closed loop at 1 kHz (a turning 0.3 m/s setpoint), then times
each `step` alone on the warmed-up state. Numbers depend on the machine; use them to compare
changes, not as real-time claims.
"""

from __future__ import annotations

import sys

import numpy as np

from hapticop.devices.ropod.controller import PlatformVelocityController
from hapticop.devices.ropod.pdo import new_rx_image, new_tx_image
from hapticop.devices.ropod.plant import RopodPlant
from hapticop.measure import time_per_call


def main(cycles: int = 2000) -> None:
    ctrl, plant = PlatformVelocityController(), RopodPlant()
    tx, rx, v_meas = new_tx_image(4), new_rx_image(4), np.zeros(3)
    setpoint = np.array([0.3, 0.0, 0.3])
    plant.write_sensors(tx)
    for _ in range(1000):
        ctrl.step(setpoint, tx, rx, v_meas)
        plant.step(rx, 0.001, tx)
    rows = {
        "controller.step": lambda: ctrl.step(setpoint, tx, rx, v_meas),
        "plant.step (RK4, 1 substep)": lambda: plant.step(rx, 0.001, tx),
        "  controller bank (11 ch)": lambda: ctrl.bank.step(ctrl._err, ctrl._y, ctrl._reset),
        "  kinematics.update": lambda: ctrl.kinematics.update(ctrl.delta, ctrl.unit_enable),
    }
    print(f"numpy {np.__version__}, {cycles} calls x 5 runs")
    for name, fn in rows.items():
        median, p99 = time_per_call(fn, cycles)
        print(f"{name:32s} median {median:7.1f} us   p99 {p99:7.1f} us")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 2000)
