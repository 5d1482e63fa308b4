"""Environmental force models: what the operator feels from the scan, added to the centring PD.

One interface, four models, each with its parameter set; the set's ``kind`` names the model (as
the haptic controller's ``force_model`` parameter does):

``none``              F0: zero; the baseline.
``thesis``            Thesis eq. 5.5/5.6 exactly as written (see ``ThesisForce`` for what that does).
``thesis_corrected``  F1 of docs/hallway-experiment.md §1/§4: the same field made restoring on z.
``braking_field``     M1 of docs/hallway-experiment.md §9.1: footprint clearance, braking-ratio risk, predictive
                      lateral clearance. The recommended model (with the S1 governor).

Every model is configured once with the scan angles (robot frame, rad, 0 ahead, + left) and the
robot's body, so that everything that depends only on the scan geometry is precomputed, then
``compute`` runs per servo cycle: vectorised over the beams, into preallocated arrays, allocating
nothing. Forces are in the handle frame of ``hapticop.haptics.handle`` (+x right, +z towards the
operator). A new model is a ``ForceModel`` subclass and its parameter set, both added to
``FORCE_MODELS`` and ``ForceModelParams`` below.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from typing import Annotated, ClassVar, Literal

import numpy as np
from annotated_types import Ge, Gt, Lt
from numpy.typing import ArrayLike, NDArray

from hapticop.devices.ropod.body import Body
from hapticop.haptics.geometry import BeamGeometry
from hapticop.haptics.handle import (
    BACKWARD_FORCE_Z,
    HANDLE_X,
    HANDLE_Y,
    HANDLE_Z,
    RIGHTWARD_FORCE_X,
    TWIST_VX,
    TWIST_VY,
)
from hapticop.haptics.scan_field import RANGE
from hapticop.parameters import parameters

Vec = NDArray[np.float64]


class ForceModel(ABC):
    """Environmental force at the handle from the latest scan, the handle position and the robot's motion.

    Two phases, because the scan changes at 15 Hz and the handle at 1 kHz: ``update_scan`` does
    the work that depends on the scan only (call it when a scan arrives), ``render`` the work
    that depends on the handle and the robot's velocity (call it every servo cycle).
    ``compute`` does both, for a caller that does not track scan arrival.
    """

    name: ClassVar[str]

    def configure(self, angles: ArrayLike, body: Body = Body()) -> None:
        """Fix the scan geometry (the angles of the ranges to come, the body they are seen from)
        and allocate work arrays."""
        self.angles = np.asarray(angles, dtype=np.float64).copy()
        self.n = self.angles.shape[0]

    def reset(self) -> None:
        """Forget internal state (rate limiters), e.g. when the controller restarts."""

    def update_scan(self, ranges: NDArray[np.floating]) -> None:
        """Take a new scan: (n,) ranges in m from the scanner, NaN where invalid."""

    def update_field(self, field: NDArray[np.float64]) -> None:
        """Take a scan already rendered beside the loop (``hapticop.haptics.scan_field``; configure
        with its angles row): the same state as ``update_scan`` of its filtered ranges."""
        self.update_scan(field[RANGE])

    @abstractmethod
    def render(self, handle_pos: Vec, robot_twist: Vec, out_force: Vec, scan_age_s: float = 0.0,
               travel: Vec | None = None) -> Vec:
        """Write the environmental force (N, handle frame) into ``out_force`` and return it.

        ``handle_pos``: (3,) m, handle frame. ``robot_twist``: (3,) measured ``[vx, vy, wz]``.
        ``scan_age_s``: how old the scan is now, for models that predict to the present.
        ``travel``: the robot's motion ``[dx, dy, dθ]`` since the scan, in the scan's frame, when a
        predictor knows it (model-mediated rendering, ``hapticop.haptics.prediction``); it then
        replaces the model's own ``robot_twist·scan_age_s``.
        """

    def compute(
        self,
        handle_pos: Vec,
        ranges: NDArray[np.floating],
        robot_twist: Vec,
        out_force: Vec,
        scan_age_s: float = 0.0,
    ) -> Vec:
        """``update_scan(ranges)`` then ``render(...)``: one full evaluation."""
        self.update_scan(ranges)
        return self.render(handle_pos, robot_twist, out_force, scan_age_s)


@parameters
class NoForceParams:
    """F0 has no parameters."""

    kind: Literal["none"] = "none"


class NoForce(ForceModel):
    """F0: no environmental force."""

    name = "none"

    def __init__(self, params: NoForceParams = NoForceParams()) -> None:
        self.params = params

    def render(self, handle_pos: Vec, robot_twist: Vec, out_force: Vec, scan_age_s: float = 0.0,
               travel: Vec | None = None) -> Vec:
        out_force.fill(0.0)
        return out_force


@parameters
class ThesisParams:
    """Scales of eq. 5.5/5.6, for the field as written (``thesis``) or with its z branch centring
    (``thesis_corrected``). The thesis tunes them by experiment; defaults are docs/hallway-experiment.md's F1 values."""

    k3_n_per_m: Annotated[float, Ge(0)] = 100.0
    """z scale: at most k3·|z| of extra force (eq. 5.5)."""
    k4_n_per_m: Annotated[float, Ge(0)] = 100.0
    """x scale: at most k4·|x| (eq. 5.6)."""
    d_max_m: Annotated[float, Gt(0)] = 2.0
    """Obstacles at or beyond this range exert no force."""
    kind: Literal["thesis", "thesis_corrected"] = "thesis"


class ThesisForce(ForceModel):
    """Thesis eq. 5.5 and 5.6, literally.

    ``F_z =  k3·z·M1`` for z ≥ 0, ``−k3·z·M2`` for z < 0; ``F_x = k4·x·M3`` for x ≥ 0, ``−k4·x·M4``
    for x < 0, with ``M_k = max_i h_k(d_i)·(d_i − d_max)/d_max·trig(θ_d,i)`` where ``max`` returns
    the value with the largest absolute value (the thesis says so explicitly; a numeric max of
    these non-positive or non-negative terms would pick the farthest obstacle, or zero, docs/hallway-experiment.md §1).
    Regions: h1 sin θ_d < 0 (behind), h2 sin θ_d > 0 (ahead), h3 cos θ_d > 0 (right),
    h4 cos θ_d < 0 (left), each also requiring d_i < d_max. NaN ranges fail ``d < d_max``.

    Angle convention: the h-functions put "ahead" at sin θ_d > 0 and the right-turn side at
    cos θ_d > 0 (fig. 5.5: x > 0 turns right), so θ_d is counter-clockwise from the robot's
    right: θ_d = φ + 90° for a robot-frame angle φ (0 ahead, + left). sin θ_d = cos φ,
    cos θ_d = −sin φ.

    What it does, sign by sign (the quirk): on x the terms have the sign that makes
    ``F_x = −k4·ρ·x`` (ρ = the largest (1 − d/d_max)·|trig| in the half-plane steered into):
    extra centring stiffness, as intended. On z both branches come out as ``F_z = +k3·ρ·z``:
    the force points *along* the displacement. Pushing forward towards a wall pulls the handle
    further forward; the z stiffness drops to Kp − k3·ρ, negative once ρ > Kp/k3 (0.55 for the
    defaults), so near an obstacle the handle runs to the workspace edge (full speed). Magnitudes
    are as the thesis states: at most k3·|z| and k4·|x|. ``CorrectedThesisForce`` flips z.

    As in the thesis, the robot is a point at the scanner and the input is the 809 points of
    the 3-beam moving average: configure with ``MovingAverage.configure(raw_angles)``'s result.
    """

    name = "thesis"

    #: Rows of ``extremes``: which region feeds which branch.
    BACK, FRONT, RIGHT, LEFT = 0, 1, 2, 3

    def __init__(self, params: ThesisParams = ThesisParams()) -> None:
        self.params = params
        self.extremes = np.zeros(4)
        """Signed max-abs value of each region for the last scan (M1..M4 above)."""

    def configure(self, angles: ArrayLike, body: Body = Body()) -> None:
        super().configure(angles, body)
        sin_d = np.cos(self.angles)  # sin θ_d
        cos_d = -np.sin(self.angles)  # cos θ_d
        # Precomputed per beam: trig(θ_d)/d_max, so a term is trig/d_max·(d − d_max).
        self._trig = np.stack([sin_d, cos_d]) / self.params.d_max_m
        n = self.n
        self._ranges = np.empty(n)
        self._excess = np.empty(n)
        self._terms = np.empty((2, n))
        self._hi = np.empty(2)
        self._lo = np.empty(2)

    def update_scan(self, ranges: NDArray[np.floating]) -> None:
        """Region extremes M1..M4 of a scan into ``self.extremes`` (they depend on the scan only).

        Each region's terms have one sign: (d − d_max) < 0 inside d_max, and h_k fixes the trig
        sign (h1: sin < 0, so terms ≥ 0; h2: ≤ 0; h3: cos > 0, ≤ 0; h4: ≥ 0). So the largest-magnitude
        term of h1 is the largest of all ``sin``-terms if positive (else h1 is empty: 0), of h2 the
        smallest if negative, and likewise for cos. Two products and four reductions give exactly
        the four max-abs values (the tests check this against a beam-by-beam transcription).
        """
        d, excess, terms = ranges, self._excess, self._terms
        if d.dtype != np.float64:  # convert once: mixed-type ufuncs allocate cast buffers
            np.copyto(self._ranges, d)
            d = self._ranges
        # The distance test of h_k times (d − d_max): d − d_max where d < d_max, else 0.
        # fmin also maps NaN (an invalid beam fails d < d_max) to 0.
        np.subtract(d, self.params.d_max_m, out=excess)
        np.fmin(excess, 0.0, out=excess)
        np.multiply(self._trig[0], excess, out=terms[0])  # row by row: a broadcast multiply
        np.multiply(self._trig[1], excess, out=terms[1])  # would allocate a (2, n) buffer
        np.maximum.reduce(terms, axis=1, out=self._hi)
        np.minimum.reduce(terms, axis=1, out=self._lo)
        m = self.extremes
        m[self.BACK] = max(float(self._hi[0]), 0.0)
        m[self.FRONT] = min(float(self._lo[0]), 0.0)
        m[self.RIGHT] = min(float(self._lo[1]), 0.0)
        m[self.LEFT] = max(float(self._hi[1]), 0.0)

    def _render(self, x: float, z: float, out_force: Vec) -> None:
        p, m = self.params, self.extremes
        fz = p.k3_n_per_m * z * float(m[self.BACK]) if z >= 0 else -p.k3_n_per_m * z * float(m[self.FRONT])
        fx = p.k4_n_per_m * x * float(m[self.RIGHT]) if x >= 0 else -p.k4_n_per_m * x * float(m[self.LEFT])
        out_force[HANDLE_X] = fx
        out_force[HANDLE_Y] = 0.0
        out_force[HANDLE_Z] = fz

    def render(self, handle_pos: Vec, robot_twist: Vec, out_force: Vec, scan_age_s: float = 0.0,
               travel: Vec | None = None) -> Vec:
        self._render(float(handle_pos[HANDLE_X]), float(handle_pos[HANDLE_Z]), out_force)
        return out_force


class CorrectedThesisForce(ThesisForce):
    """F1 of docs/hallway-experiment.md (§1, §4): the thesis field with the intended signs, ``F = −k·ρ·p`` on both axes.

    Same regions, same max-abs choice, same magnitudes as ``ThesisForce``; only the z sign differs,
    so both axes add centring stiffness (Kp up to Kp + k3) instead of removing it on z. docs/hallway-experiment.md
    write F1's z term for z < 0 only; the thesis's reversing branch (obstacles behind, z ≥ 0) is
    kept, with the same restoring sign.
    Kept because docs/hallway-experiment.md use it as the source-field reference condition; it still has every
    limitation of §1 (cannot stop a pushing operator, no lateral cue with a centred handle,
    point-robot distances, beam switching).
    """

    name = "thesis_corrected"

    def __init__(self, params: ThesisParams = ThesisParams(kind="thesis_corrected")) -> None:
        super().__init__(params)

    def _render(self, x: float, z: float, out_force: Vec) -> None:
        p, m = self.params, self.extremes
        rho_z = abs(float(m[self.BACK] if z >= 0 else m[self.FRONT]))
        rho_x = abs(float(m[self.RIGHT] if x >= 0 else m[self.LEFT]))
        out_force[HANDLE_X] = -p.k4_n_per_m * rho_x * x
        out_force[HANDLE_Y] = 0.0
        out_force[HANDLE_Z] = -p.k3_n_per_m * rho_z * z


@parameters
class BrakingFieldParams:
    """M1, the braking field: footprint clearance, braking-ratio risk, predictive lateral clearance.

    Defaults from docs/hallway-experiment.md §2 and §9.1 unless marked as our choice."""

    side_distance_m: Annotated[float, Ge(0)] = 0.40
    """dist1: comfortable side clearance (H1/H2)."""
    stop_distance_m: Annotated[float, Ge(0)] = 0.50
    """dist2: front-of-footprint clearance at the stop."""
    bumper_m: Annotated[float, Ge(0)] = 0.10
    """dist3: virtual bumper; the lateral cue is full here."""
    corridor_margin_m: Annotated[float, Ge(0)] = 0.10
    """m_c, corridor half-width beyond the body. Not given in docs/hallway-experiment.md; our choice (= dist3) keeps
    the side walls of the 1.5 m H3 hall (0.45 m beside the body) out of the stop corridor."""
    brake_decel_mps2: Annotated[float, Gt(0)] = 0.5
    """a_b: braking capacity the risk is measured against."""
    silent_ratio: Annotated[float, Ge(0), Lt(1)] = 0.4
    """r0: no longitudinal cue below 40 % of braking capacity (v/v_allow)."""
    proximity_gap_m: Annotated[float, Gt(0)] = 0.3
    """g_p: proximity risk ramps in over the last 0.3 m before the stop line, even at standstill."""
    longitudinal_risk: Literal["braking", "ttc"] = "braking"
    """"braking": v/v_allow (docs/hallway-experiment.md's choice); "ttc": the time-to-collision alternative."""
    ttc_horizon_s: Annotated[float, Gt(0)] = 4.0
    """T_h: TTC risk starts below this."""
    ttc_min_s: Annotated[float, Ge(0)] = 1.0
    """T_min: TTC risk is full at or below this."""
    fz_max_n: Annotated[float, Ge(0)] = 6.0
    """Longitudinal cue at full risk and full handle ramp (≤ 8 N target, §6)."""
    z_ramp_m: Annotated[float, Gt(0)] = 0.02
    """z_g: the cue ramps over the first 2 cm of forward push (300 N/m slope, inside the L0 budget)."""
    window_rear_m: Annotated[float, Ge(0)] = 0.5
    """Side window reaches this far behind the body."""
    window_ahead_m: Annotated[float, Ge(0)] = 1.5
    """Side window reaches this far ahead of the body."""
    side_margin_m: Annotated[float, Ge(0)] = 0.25
    """m_l: the lateral cue starts at dist1 + m_l of predicted clearance."""
    lead_time_s: Annotated[float, Ge(0)] = 1.5
    """T_p: lateral prediction horizon (the phase lead §7.5 requires)."""
    fx_max_n: Annotated[float, Ge(0)] = 5.0
    """Lateral cue at full risk on one side."""
    lateral_edge_m: Annotated[float, Gt(0)] = 0.045
    """The lateral cue fades out as the handle, pushed its way, nears this displacement: the Falcon's
    workspace ends at 5 cm, and a soft hand pushed there gains no more steering (our choice)."""
    lateral_fade_m: Annotated[float, Gt(0)] = 0.015
    """The fade's width: full cue up to ``lateral_edge_m − lateral_fade_m`` of push (7 N over 1.5 cm is
    470 N/m, inside the 600 N/m the longitudinal ramp already asks of §7.2's damping)."""
    lateral_speed_ref_mps: Annotated[float, Gt(0)] = 0.25
    """v_ref: lateral cue scales with sat(|v|/v_ref), none at standstill. Not given in docs/hallway-experiment.md;
    our choice is just below the cautious operator's 0.28 m/s cruise."""
    robust_k: Annotated[int, Ge(1)] = 3
    """Robust minimum: the k-th smallest clearance (docs/hallway-experiment.md's "3rd smallest")."""
    risk_rate_per_s: Annotated[float, Gt(0)] = 3.0
    """|dρ/dt| limit on the risk state (ρ_z, e_L, e_R): bounds the force step at scan arrival."""
    side_risk_rate_per_s: Annotated[float, Gt(0)] | None = None
    """|de/dt| limit on the lateral risks e_L, e_R alone; None: ``risk_rate_per_s``. The lateral loop has its
    own pace: a cue slowed to calm the stop comes too late to turn the robot off a wall
    (docs/hallway-experiment.md §9.1)."""
    period_s: Annotated[float, Gt(0)] = 0.001
    """Time between ``render`` (or ``compute``) calls, for the rate limiter."""
    kind: Literal["braking_field"] = "braking_field"

    def __post_init__(self) -> None:
        if not self.bumper_m < self.side_distance_m + self.side_margin_m:
            raise ValueError("the lateral cue needs bumper_m < side_distance_m + side_margin_m")
        if not self.ttc_min_s < self.ttc_horizon_s:
            raise ValueError("the TTC risk needs ttc_min_s < ttc_horizon_s")


def _sat01(u: float) -> float:
    return 0.0 if not u > 0.0 else (1.0 if u > 1.0 else u)


class BrakingField(ForceModel):
    """M1: footprint + braking-ratio risk + predictive lateral clearance (docs/hallway-experiment.md §9.1).

    Longitudinal, a resisting force while pushing forward::

        g      = kth_min over the corridor of (p_x − L/2) − dist2 − v·age    predicted gap to the stop line
        ρ_brk  = sat((v/√(2·a_b·g⁺) − r0)/(1 − r0))                          required vs available braking
        ρ_prx  = sat(1 − g/g_p)                                               near the stop line, any speed
        ρ_z    = 1 − (1 − ρ_brk)(1 − ρ_prx)                                   smooth max (soft OR)
        F_z    = +F_z,max·ρ_z·sat(−z/z_g)   for z < 0                         pushes the hand back

    Lateral, additive (felt with a centred handle), phase lead in both directions::

        c_L, c_R = kth_min footprint clearance per side after translating by v·(age + T_p)
        e_S      = sat((dist1 + m_l − c_S)/(dist1 + m_l − dist3))
        F_x      = F_x,max·(e_L − e_R)·sat(|v|/v_ref)·sat((x_e − x_push)/x_f)  towards the freer side
                   fading out as the handle, pushed x_push along the cue, nears the workspace edge

    Translating by v·T_p equals docs/hallway-experiment.md's c + T_p·ċ for a straight wall; ċ comes from the
    measured robot velocity, not from ω, so no handle-proportional term crosses the network
    (§7.3). ρ_z, e_L, e_R are rate-limited. Diagnostics of the last call: ``gap_m``,
    ``rho_brake``, ``rho_prox``, ``c_left_m``, ``c_right_m`` and the rate-limited ``risk``.
    """

    name = "braking_field"

    def __init__(self, params: BrakingFieldParams = BrakingFieldParams()) -> None:
        self.params = params
        self.risk = np.zeros(3)
        """Rate-limited risk state [ρ_z, e_L, e_R]: the scalars that may cross the network."""
        self.reset()

    def configure(self, angles: ArrayLike, body: Body = Body()) -> None:
        super().configure(angles, body)
        self.beams = BeamGeometry(self.angles, body)
        self._corridor_gap = math.inf

    def reset(self) -> None:
        self.risk.fill(0.0)
        self.gap_m = math.inf
        self.rho_brake = self.rho_prox = 0.0
        self.c_left_m = self.c_right_m = math.inf

    def longitudinal_risk(self, gap_m: float, v_mps: float) -> float:
        """Target ρ_z for a predicted gap to the stop line and a forward speed."""
        p = self.params
        if p.longitudinal_risk == "ttc":
            if v_mps <= 0.0:
                urgency = 0.0
            else:
                urgency = _sat01((p.ttc_horizon_s - gap_m / v_mps) / (p.ttc_horizon_s - p.ttc_min_s))
        else:
            v_allow = math.sqrt(2.0 * p.brake_decel_mps2 * gap_m) if gap_m > 0.0 else 0.0
            if v_mps <= 0.0:
                ratio = 0.0
            elif v_allow <= 0.0:
                ratio = math.inf
            else:
                ratio = v_mps / v_allow
            urgency = _sat01((ratio - p.silent_ratio) / (1.0 - p.silent_ratio))
        prox = _sat01(1.0 - gap_m / p.proximity_gap_m)
        self.rho_brake, self.rho_prox = urgency, prox
        return 1.0 - (1.0 - urgency) * (1.0 - prox)

    def update_scan(self, ranges: NDArray[np.floating]) -> None:
        self.beams.load(ranges)
        self._points_loaded()

    def update_field(self, field: NDArray[np.float64]) -> None:
        self.beams.load_points(field)  # the points are the field's: two copies, no trigonometry
        self._points_loaded()

    def _points_loaded(self) -> None:
        """The scan's corridor gap and side points, once per scan."""
        p, beams = self.params, self.beams
        self._corridor_gap = beams.corridor_gap(p.corridor_margin_m, p.robust_k)
        beams.select_sides(p.window_rear_m, p.window_ahead_m)

    def render(self, handle_pos: Vec, robot_twist: Vec, out_force: Vec, scan_age_s: float = 0.0,
               travel: Vec | None = None) -> Vec:
        p = self.params
        vx = float(robot_twist[TWIST_VX])
        vy = float(robot_twist[TWIST_VY])
        if travel is None:
            moved_x, moved_y = vx * scan_age_s, vy * scan_age_s
        else:
            moved_x, moved_y = float(travel[0]), float(travel[1])
        gap = self._corridor_gap - p.stop_distance_m - moved_x
        self.gap_m = gap
        rho_z = self.longitudinal_risk(gap, vx)
        lead = p.lead_time_s
        c_left, c_right = self.beams.side_clearances(moved_x + vx * lead, moved_y + vy * lead, p.robust_k)
        self.c_left_m, self.c_right_m = c_left, c_right
        start = p.side_distance_m + p.side_margin_m
        band = start - p.bumper_m
        # The risk state, each part moved towards its target by at most the rate limit's step.
        step = p.risk_rate_per_s * p.period_s
        side_step = step if p.side_risk_rate_per_s is None else p.side_risk_rate_per_s * p.period_s
        risk = self.risk
        r_z, r_left, r_right = risk.tolist()
        r_z += _step_towards(r_z, rho_z, step)
        r_left += _step_towards(r_left, _sat01((start - c_left) / band), side_step)
        r_right += _step_towards(r_right, _sat01((start - c_right) / band), side_step)
        risk[0], risk[1], risk[2] = r_z, r_left, r_right
        z = float(handle_pos[HANDLE_Z])
        fz = BACKWARD_FORCE_Z * p.fz_max_n * r_z * _sat01(-z / p.z_ramp_m) if z < 0.0 else 0.0
        speed_scale = _sat01(abs(vx) / p.lateral_speed_ref_mps)
        # Push towards the side with less risk: the right (+x) when the left wall is nearer.
        fx = RIGHTWARD_FORCE_X * p.fx_max_n * (r_left - r_right) * speed_scale
        pushed = float(handle_pos[HANDLE_X]) if fx > 0.0 else -float(handle_pos[HANDLE_X])  # along the cue
        fx *= _sat01((p.lateral_edge_m - pushed) / p.lateral_fade_m)
        out_force[HANDLE_X] = fx
        out_force[HANDLE_Y] = 0.0
        out_force[HANDLE_Z] = fz
        return out_force


def _step_towards(now: float, target: float, step: float) -> float:
    """The change that moves ``now`` towards ``target`` by at most ``step`` (the risk's rate limit)."""
    return max(-step, min(step, target - now))


FORCE_MODELS: dict[str, type[ForceModel]] = {
    NoForce.name: NoForce,
    ThesisForce.name: ThesisForce,
    CorrectedThesisForce.name: CorrectedThesisForce,
    BrakingField.name: BrakingField,
}

ForceModelParams = NoForceParams | ThesisParams | BrakingFieldParams
"""The parameters of one force model; their ``kind`` names it (a key of ``FORCE_MODELS``)."""


def make_force_model(
    model: str | ForceModelParams, angles: ArrayLike | None = None, body: Body = Body()
) -> ForceModel:
    """Build the model its parameters name, or a model by name with its defaults; configured if angles are given."""
    kind = model if isinstance(model, str) else model.kind
    try:
        cls = FORCE_MODELS[kind]
    except KeyError:
        raise ValueError(f"unknown force model {kind!r}; known: {sorted(FORCE_MODELS)}") from None
    built = cls() if isinstance(model, str) else cls(model)  # type: ignore[call-arg]
    if angles is not None:
        built.configure(angles, body)
    return built
