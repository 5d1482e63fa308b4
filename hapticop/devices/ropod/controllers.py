"""The ropod's generic linear controller "G_I_LL_LPF" as a bank of independent channels.

One chain per channel: gain -> PI whose *output* is clamped to +-S with clamping
anti-windup -> lead-lag -> first-order low-pass, each the Tustin (bilinear, no prewarp)
discretisation at Ts. The order and the integrator update follow the Simulink-generated
code (ropod-controller.md §6.2), so the saturated and reset behaviour match the ropod,
not just the linear transfer function. The ropod runs eleven of these (x, y, theta and
eight wheels); a bank steps them all with a fixed number of numpy calls and no allocation.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "LinearControllerParams", "ControllerBank",
    "THESIS_PLATFORM_XY", "THESIS_PLATFORM_THETA", "THESIS_WHEEL",
    "ROPOD2019_PLATFORM_XY", "ROPOD2019_PLATFORM_THETA",
    "HOSPITAL2018_PLATFORM_XY", "HOSPITAL2018_PLATFORM_THETA", "ROPOD_PIVOT_DAMPING",
]

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class LinearControllerParams:
    """Parameters in the thesis's / ropod's names; frequencies in Hz, each a scalar or a per-channel array.

    `i_fhz = 0` makes the PI a pure gain; `ll_zero_fhz == ll_pole_fhz` removes the lead-lag.
    `i_saturation` (the thesis's "I saturation", ropod's `i_sat`) clamps the PI *output*.
    """

    p_gain: float | F64
    i_fhz: float | F64
    ll_zero_fhz: float | F64
    ll_pole_fhz: float | F64
    lpf_fhz: float | F64
    i_saturation: float | F64

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> "LinearControllerParams":
        """Accept both the block's `i_saturation` and reference.json's `i_sat`."""
        data = {k: v for k, v in values.items() if k in {f.name for f in fields(cls)}}
        if "i_sat" in values and "i_saturation" not in data:
            data["i_saturation"] = values["i_sat"]
        return cls(**data)

    @classmethod
    def stack(cls, channels: Sequence["LinearControllerParams"]) -> "LinearControllerParams":
        """One parameter set of per-channel arrays from one set per channel."""
        return cls(**{f.name: np.array([np.float64(getattr(c, f.name)) for c in channels])
                      for f in fields(cls)})


# Parameter sets of ropod-controller.md §6.3 (platform K in N/(m/s) or Nm/(rad/s), wheel K in Nm/(rad/s)).
THESIS_PLATFORM_XY = LinearControllerParams(100.0, 0.25, 20.0, 20.0, 100.0, 100.0)
THESIS_PLATFORM_THETA = LinearControllerParams(755.0, 0.3, 20.0, 20.0, 100.0, 100.0)
THESIS_WHEEL = LinearControllerParams(0.05, 0.0, 2.0, 10.0, 50.0, 7.0)
ROPOD2019_PLATFORM_XY = LinearControllerParams(200.0, 0.25, 20.0, 20.0, 100.0, 500.0)
ROPOD2019_PLATFORM_THETA = LinearControllerParams(150.0, 0.3, 20.0, 20.0, 100.0, 250.0)
HOSPITAL2018_PLATFORM_XY = LinearControllerParams(150.0, 0.25, 20.0, 20.0, 100.0, 500.0)
HOSPITAL2018_PLATFORM_THETA = LinearControllerParams(100.0, 0.3, 20.0, 20.0, 100.0, 250.0)
ROPOD_PIVOT_DAMPING = LinearControllerParams(0.1, 0.0, 2.0, 2.0, 50.0, 7.0)


class ControllerBank:
    """`n` generic controllers stepped together; state and scratch preallocated.

    `params` holds scalars (shared) or length-`n` arrays; `n` is taken from the arrays
    unless given. `step(error, out, reset)` writes the `n` outputs into `out`.
    """

    def __init__(self, params: LinearControllerParams, ts: float, n: int | None = None):
        cols = {f.name: np.asarray(getattr(params, f.name), np.float64) for f in fields(params)}
        if n is None:
            n = max((c.size for c in cols.values() if c.ndim), default=1)
        p = {k: np.broadcast_to(v, (n,)).astype(np.float64) for k, v in cols.items()}
        if ts <= 0 or np.any(p["i_saturation"] <= 0) or np.any(p["i_fhz"] < 0):
            raise ValueError("need ts > 0, i_saturation > 0 and i_fhz >= 0")
        if np.any(p["ll_zero_fhz"] <= 0) or np.any(p["ll_pole_fhz"] <= 0) or np.any(p["lpf_fhz"] <= 0):
            raise ValueError("lead-lag and low-pass frequencies must be > 0")
        self.n, self.ts = n, float(ts)
        h = ts / 2.0
        two_pi = 2.0 * math.pi
        w_p = two_pi * p["ll_pole_fhz"]
        w_l = two_pi * p["lpf_fhz"]
        a_n = w_p * h
        self._k = p["p_gain"]
        self._sat = p["i_saturation"]
        self._neg_sat = -self._sat
        self._h_wi = h * two_pi * p["i_fhz"]  # h*ui = (h*wi)*x
        self._dd = 1.0 / (two_pi * p["ll_zero_fhz"]) - 1.0 / w_p  # lead-lag "D" of the PID form
        self._ll_a = (1.0 - a_n) / (1.0 + a_n)
        self._ll_b = w_p / (1.0 + a_n)
        self._g = w_l * h / (1.0 + w_l * h)
        self._lp_a = 1.0 - 2.0 * self._g
        # States: PI integrator, lead-lag, low-pass; level-reset memory.
        self.xi = np.zeros(n)
        self.xd = np.zeros(n)
        self.xl = np.zeros(n)
        self._prev_reset = np.zeros(n, bool)
        # Per-stage outputs of the last step (read-only use: diagnostics and tests).
        self.y_pi = np.zeros(n)
        self.y_leadlag = np.zeros(n)
        self.clamped = np.zeros(n, bool)
        # Scratch.
        self._x = np.zeros(n)
        self._chk = np.zeros(n)
        self._hui = np.zeros(n)
        self._w = np.zeros(n)
        self._b1 = np.zeros(n, bool)
        self._b2 = np.zeros(n, bool)

    def reset(self) -> None:
        """All states to zero, as at start."""
        self.xi.fill(0.0)
        self.xd.fill(0.0)
        self.xl.fill(0.0)
        self._prev_reset.fill(False)

    def step(self, error: ArrayLike, out: F64, reset: NDArray[np.bool_] | None = None) -> F64:
        """One sample: `out[:] = C(error)`. `reset` (bool per channel) zeroes the integrator (level reset)."""
        x, chk, hui, b1, b2 = self._x, self._chk, self._hui, self._b1, self._b2
        np.multiply(self._k, error, out=x)
        # PI with clamping anti-windup. The clamp test uses the state before any reset.
        np.add(x, self.xi, out=chk)
        if reset is not None:
            np.logical_or(reset, self._prev_reset, out=b1)
            np.copyto(self.xi, 0.0, where=b1)
            np.copyto(self._prev_reset, reset)
        elif self._prev_reset.any():
            np.copyto(self.xi, 0.0, where=self._prev_reset)
            self._prev_reset.fill(False)
        np.multiply(self._h_wi, x, out=hui)
        # Stop integrating when the unclamped output is beyond +-S and the input pushes further.
        np.greater(chk, self._sat, out=b1)
        np.greater(hui, 0.0, out=b2)
        np.logical_and(b1, b2, out=b1)
        np.copyto(self.clamped, b1)
        np.less(chk, self._neg_sat, out=b1)
        np.less(hui, 0.0, out=b2)
        np.logical_and(b1, b2, out=b1)
        np.logical_or(self.clamped, b1, out=self.clamped)
        np.copyto(hui, 0.0, where=self.clamped)
        xi = self.xi
        xi += hui  # trapezoidal integrator output yi = xi + h*ui
        np.add(x, xi, out=self.y_pi)
        np.minimum(self.y_pi, self._sat, out=self.y_pi)
        np.maximum(self.y_pi, self._neg_sat, out=self.y_pi)
        xi += hui  # state update: xi += Ts*ui
        # Lead-lag: Tustin of 1 + Dd*wp*s/(s + wp).
        w = self._w
        np.multiply(self._dd, self.y_pi, out=w)
        np.multiply(self._ll_a, self.xd, out=hui)
        w += hui  # wk
        np.subtract(w, self.xd, out=hui)
        hui *= self._ll_b
        np.add(self.y_pi, hui, out=self.y_leadlag)
        np.copyto(self.xd, w)
        # Low-pass: Tustin of wl/(s + wl).
        np.add(self.y_leadlag, self.xl, out=w)  # wl
        np.multiply(self._g, w, out=out)
        np.multiply(self._lp_a, w, out=self.xl)
        self.xl += self.y_leadlag
        return out
