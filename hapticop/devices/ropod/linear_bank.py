"""The ropod's generic linear controller "G_I_LL_LPF" as a bank of independent channels.

One chain per channel: gain -> PI whose *output* is clamped to +-S with clamping
anti-windup -> lead-lag -> first-order low-pass, each the Tustin (bilinear, no prewarp)
discretisation at Ts. The order and the integrator update follow the Simulink-generated
code (docs/devices/ropod.md §6.2), so the saturated and reset behaviour match the ropod,
not just the linear transfer function. The ropod runs eleven of these (x, y, theta and
eight wheels); a bank steps them all on Python floats with no allocation. `linear_bank.pxd`
types the bank's step for Cython (setup.py; the same bits: tests/test_compiled_kernels.py).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import fields

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hapticop.devices.ropod.controller_params import LinearControllerParams

__all__ = ["ControllerBank"]

F64 = NDArray[np.float64]


class ControllerBank:
    """`n` generic controllers stepped together; state and scratch preallocated.

    `params` is one parameter set shared by the `n` channels, or one set per channel (then
    `n` is their number unless given). `step(error, out, reset)` writes the `n` outputs into `out`. The channels
    run on Python floats (a dozen channels are too few for numpy to pay off); `step_values`
    is the same step on float sequences, for callers that keep their signals in floats.
    The states (`xi`, `xd`, `xl`) and last step's stage outputs (`y_pi`, `y_leadlag`,
    `clamped`) read as arrays, made on access (diagnostics and tests).
    """

    def __init__(self, params: LinearControllerParams | Sequence[LinearControllerParams], ts: float,
                 n: int | None = None):
        if n is None:
            n = 1 if isinstance(params, LinearControllerParams) else len(params)
        self.n, self.ts = n, float(ts)
        self._coef = self._coefficients(params)
        # States: PI integrator, lead-lag, low-pass; level-reset memory.
        self._xi, self._xd, self._xl = [0.0] * n, [0.0] * n, [0.0] * n
        self._prev_reset = [False] * n
        # Per-stage outputs of the last step.
        self._y_pi, self._y_leadlag, self._clamped = [0.0] * n, [0.0] * n, [False] * n
        self._no_reset = (False,) * n
        self._error, self._reset, self._out = [0.0] * n, [False] * n, [0.0] * n

    def _coefficients(self, params: LinearControllerParams | Sequence[LinearControllerParams]) -> tuple:
        """Per channel: gain, saturation, h*wi, lead-lag D, a, b, low-pass g, a (Tustin at `ts`)."""
        channels = [params] if isinstance(params, LinearControllerParams) else list(params)
        cols = {f.name: np.array([getattr(c, f.name) for c in channels], np.float64)
                for f in fields(LinearControllerParams)}
        n, ts = self.n, self.ts
        p = {k: np.broadcast_to(v, (n,)).astype(np.float64) for k, v in cols.items()}
        if ts <= 0 or np.any(p["i_saturation"] <= 0) or np.any(p["i_fhz"] < 0):
            raise ValueError("need ts > 0, i_saturation > 0 and i_fhz >= 0")
        if np.any(p["ll_zero_fhz"] <= 0) or np.any(p["ll_pole_fhz"] <= 0) or np.any(p["lpf_fhz"] <= 0):
            raise ValueError("lead-lag and low-pass frequencies must be > 0")
        h = ts / 2.0
        two_pi = 2.0 * math.pi
        w_p = two_pi * p["ll_pole_fhz"]
        w_l = two_pi * p["lpf_fhz"]
        a_n = w_p * h
        h_wi = h * two_pi * p["i_fhz"]  # h*ui = (h*wi)*x
        dd = 1.0 / (two_pi * p["ll_zero_fhz"]) - 1.0 / w_p  # lead-lag "D" of the PID form
        ll_a = (1.0 - a_n) / (1.0 + a_n)
        ll_b = w_p / (1.0 + a_n)
        g = w_l * h / (1.0 + w_l * h)
        lp_a = 1.0 - 2.0 * g
        return tuple(zip(*(c.tolist() for c in (p["p_gain"], p["i_saturation"], h_wi, dd, ll_a, ll_b, g, lp_a))))

    def retune(self, params: LinearControllerParams | Sequence[LinearControllerParams]) -> None:
        """New gains and corner frequencies from the next step on; the states stay, so the output
        carries on from where it was instead of restarting from zero (bumpless)."""
        self._coef = self._coefficients(params)

    def reset(self) -> None:
        """All states to zero, as at start."""
        for j in range(self.n):
            self._xi[j] = self._xd[j] = self._xl[j] = 0.0
            self._prev_reset[j] = False

    xi = property(lambda self: np.array(self._xi), doc="PI integrator states")
    xd = property(lambda self: np.array(self._xd), doc="lead-lag states")
    xl = property(lambda self: np.array(self._xl), doc="low-pass states")
    y_pi = property(lambda self: np.array(self._y_pi), doc="PI output (after its clamp) of the last step")
    y_leadlag = property(lambda self: np.array(self._y_leadlag), doc="lead-lag output of the last step")
    clamped = property(lambda self: np.array(self._clamped), doc="channels whose integrator held in the last step")

    def step(self, error: ArrayLike, out: F64, reset: NDArray[np.bool_] | None = None) -> F64:
        """One sample: `out[:] = C(error)`. `reset` (bool per channel) zeroes the integrator (level reset)."""
        values, flags, result = self._error, self._reset, self._out
        error = np.asarray(error, np.float64)
        if error.shape != (self.n,) or (reset is not None and np.shape(reset) != (self.n,)):
            raise ValueError(f"a bank of {self.n} channels needs {self.n} errors and resets, got shapes "
                             f"{error.shape} and {None if reset is None else np.shape(reset)}")
        values[:] = error.tolist()
        if reset is not None:
            flags[:] = np.asarray(reset, bool).tolist()
        self.step_values(values, result, None if reset is None else flags)
        out[:] = result
        return out

    def step_values(self, error: Sequence[float], out: list, reset: Sequence[bool] | None = None) -> None:
        """`step` on Python floats: `out[j] = C_j(error[j])`."""
        xi_, xd_, xl_, prev = self._xi, self._xd, self._xl, self._prev_reset
        y_pi, y_ll, clamped_ = self._y_pi, self._y_leadlag, self._clamped
        if reset is None:
            reset = self._no_reset
        for j, (e, r, (k, sat, h_wi, dd, ll_a, ll_b, g, lp_a)) in enumerate(zip(error, reset, self._coef)):
            x = k * e
            if h_wi:
                xi = xi_[j]
                chk = x + xi  # the clamp test uses the state before any reset
                if r or prev[j]:
                    xi = 0.0
                prev[j] = r
                hui = h_wi * x
                # PI with clamping anti-windup: stop integrating when the unclamped output is beyond
                # +-S and the input pushes further.
                clamped = (chk > sat and hui > 0.0) or (chk < -sat and hui < 0.0)
                if clamped:
                    hui = 0.0
                xi += hui  # trapezoidal integrator output yi = xi + h*ui
                ypi = x + xi
                xi_[j] = xi + hui  # state update: xi += Ts*ui
            else:  # no integrator (i_fhz = 0): nothing to hold or reset, the PI is the clamped gain
                clamped, ypi = False, x
            if ypi > sat:
                ypi = sat
            elif ypi < -sat:
                ypi = -sat
            # Lead-lag: Tustin of 1 + Dd*wp*s/(s + wp).
            xd = xd_[j]
            w = dd * ypi + ll_a * xd
            yll = ypi + (w - xd) * ll_b
            xd_[j] = w
            # Low-pass: Tustin of wl/(s + wl).
            wl = yll + xl_[j]
            out[j] = g * wl
            xl_[j] = lp_a * wl + yll
            y_pi[j], y_ll[j], clamped_[j] = ypi, yll, clamped
