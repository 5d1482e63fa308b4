"""What a fault scenario did to the robot: from the scripted faults and the run's recording.

A scenario (systems/faults.yaml) sets a simulated device's `sim_fault` by scripted patches
and clears it later. For each window this finds when the velocity setpoint first went to
zero, when the robot came to rest, and when the operator's commands moved it again after
the fault cleared, all from the world's 1 kHz recording.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hapticop.composition.description import Composition

STILL_MPS = 0.01
"""Below this the robot is at rest."""


@dataclass(frozen=True)
class FaultWindow:
    activity: str
    fault: str
    start_ns: int  # after the system's start, as the scripted patch says
    end_ns: int | None  # when a later patch clears it; None: never


@dataclass(frozen=True)
class Reaction:
    window: FaultWindow
    to_zero_setpoint_s: float  # fault to a zero velocity setpoint (NaN: never went to zero)
    to_rest_s: float  # fault to the robot at rest
    resumed_after_s: float  # fault cleared to a setpoint moving the robot again


def fault_windows(composition: Composition) -> list[FaultWindow]:
    """Pair each scripted patch that sets an activity's `sim_fault` with the one that clears it."""
    changes: list[tuple[int, str, str]] = []
    for patch in sorted(composition.patches.values(), key=lambda p: p.at):
        activities = patch.patch.get("activities", {}) if isinstance(patch.patch, dict) else {}
        for name, spec in activities.items():
            fault = ((spec or {}).get("params") or {}).get("sim_fault")
            if fault is not None:
                changes.append((patch.at, name, fault))
    windows = []
    for index, (at, name, fault) in enumerate(changes):
        if fault == "none":
            continue
        end = next((t for t, n, f in changes[index + 1:] if n == name), None)
        windows.append(FaultWindow(name, fault, at, end))
    return windows


def reactions(t_s: np.ndarray, setpoint: np.ndarray, velocity: np.ndarray, operator_start_ns: int,
              started_ns: int, windows: list[FaultWindow]) -> list[Reaction]:
    """`t_s`, `setpoint` (T, k) and `velocity` (T, k) as the world recorded them, on the operator's time."""
    moving_cmd = np.abs(setpoint).max(axis=1) > 0.0
    moving = np.abs(velocity).max(axis=1) >= STILL_MPS
    found = []
    for w in windows:
        start = (started_ns + w.start_ns - operator_start_ns) / 1e9
        end = math.inf if w.end_ns is None else (started_ns + w.end_ns - operator_start_ns) / 1e9
        during = (t_s >= start) & (t_s < end)
        zero = np.flatnonzero(during & ~moving_cmd)
        rest = np.flatnonzero(during & ~moving)
        after = np.flatnonzero((t_s >= end) & moving_cmd)
        found.append(Reaction(
            w,
            float(t_s[zero[0]] - start) if zero.size else math.nan,
            float(t_s[rest[0]] - start) if rest.size else math.nan,
            float(t_s[after[0]] - end) if after.size and math.isfinite(end) else math.nan,
        ))
    return found
