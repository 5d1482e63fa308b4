"""The haptic controller: handle displacement to robot velocity, obstacles to force.

It holds the handle at its origin with a PD (Kp 55 N/m, Kd 0.2 Ns/m), maps displacement to
velocity setpoints with the car-driving metaphor (k1 28, k2 10, 0.5 cm dead zone) and adds
the environmental force of the chosen model, everything limited to 10 N per axis.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Interface, Params, Port, RateRange
from hapticop.haptics.force_models import BrakingFieldParams
from hapticop.haptics.governor import GovernorParams, govern_cycle, govern_scan, limit_blind, stop_gap
from hapticop.haptics.handle import CentringParams, CentringPD, DrivingParams, handle_to_twist
from hapticop.haptics.scan_filter import MovingAverage


class HapticControllerParams(Params):
    kp_n_per_m: float = Field(55.0, ge=0, description="handle-centring stiffness")
    kd_ns_per_m: float = Field(0.2, ge=0, description="handle-centring damping")
    force_limit_n: float = Field(10.0, gt=0, le=20.0, description="per-axis force saturation")
    k1: float = Field(28.0, description="forward speed per handle displacement, (m/s)/m")
    k2: float = Field(10.0, description="turn rate per handle displacement, (rad/s)/m")
    dead_zone_m: float = Field(0.005, ge=0)
    force_model: Literal["none", "thesis", "thesis_corrected", "braking_field"] = Field(
        "braking_field", description="thesis: equations 5.5/5.6 literally; thesis_corrected: their z branch "
        "centring; braking_field: footprint braking-distance risk with lateral clearance (hallway-experiment.md §9)")
    braking_field: BrakingFieldParams = Field(
        default_factory=BrakingFieldParams, description="parameters of the braking_field model (hallway-experiment.md §9.1)")
    governor: bool = Field(False, description="limit the commanded twist to what can stop before obstacles")
    centred_within_m: float = Field(0.005, gt=0, description="capability configuration ends with the handle this close")
    k3_n_per_m: float = Field(100.0, ge=0, description="environmental force scale, z (eq. 5.5)")
    k4_n_per_m: float = Field(100.0, ge=0, description="environmental force scale, x (eq. 5.6)")
    d_max_m: float = Field(2.0, gt=0, description="range beyond which obstacles exert no force")
    moving_average: int = Field(3, ge=1, description="window of the range filter (811 points give 809)")
    scan_points: int = Field(811, ge=2, le=10_000)
    blind: Literal["stop", "slow"] = Field(
        "stop", description="while the scan is stale (older than its stream's max_age): 'stop' commands no motion, "
        "'slow' limits the robot to blind_speed_mps and blind_turn_rad_s")
    blind_speed_mps: float = Field(0.1, ge=0, description="speed limit while blind (policy 'slow')")
    blind_turn_rad_s: float = Field(0.2, ge=0, description="turn-rate limit while blind (policy 'slow')")


class HapticController(Block):
    Params = HapticControllerParams
    flags_read = {"resources_ready": "the Falcon, LIDAR and ropod controller are running",
                  "robot_held": "the robot is held still (a wheel is not in OP): command no motion"}
    flags_written = {"blind": "the scan is stale: the blind policy limits the robot",
                     "handle_lost": "the handle position is stale (Falcon frames stopped): no force, no motion"}
    awaits = frozenset({"resources_ready"})
    optional_flags = frozenset({"robot_held"})  # only a composition with a fieldbus watchdog binds it
    running_params = frozenset({"blind", "blind_speed_mps", "blind_turn_rad_s"})
    capability_params = frozenset({"kp_n_per_m", "kd_ns_per_m", "force_limit_n", "k1", "k2", "dead_zone_m",
                                   "k3_n_per_m", "k4_n_per_m", "d_max_m", "governor", "braking_field",
                                   "force_model"})

    @classmethod
    def interface(cls, params: HapticControllerParams) -> Interface:
        n = (params.scan_points,)
        return Interface(
            inputs={
                "handle_position": Port("float64", (3,), "m"),
                "handle_velocity": Port("float64", (3,), "m/s"),
                "ranges": Port("float32", n, "m"),
                "angles": Port("float32", n, "rad"),
                "platform_velocity": Port("float64", (3,), "m/s, m/s, rad/s", required=False),
            },
            outputs={
                "force": Port("float64", (3,), "N", "force for the Falcon"),
                "velocity_setpoint": Port("float64", (3,), "m/s, m/s, rad/s", "platform twist [vx, vy, wz]"),
                "environment_force": Port("float64", (3,), "N", "the obstacle part of the force"),
            },
            flags_read=dict(cls.flags_read),
            flags_written=dict(cls.flags_written),
            rate=RateRange(500.0, 2000.0, "the haptic loop renders stiff forces only near 1 kHz"),
        )

    # -- life cycle -------------------------------------------------------------------------
    def create(self) -> None:
        self.handle_lost = self.blind = False  # what the flags of the same names last said

    def configure_resources(self) -> bool:
        """Wait until the Falcon, the LIDAR and the ropod controller run (the mediator says so)."""
        return self.flags["resources_ready"]

    def configure_capabilities(self) -> bool:
        """Build the control laws, then hold the handle at its origin before commanding motion."""
        if getattr(self, "built_for", None) is not self.params:  # first time, or a patch changed them
            self._build()
            self.built_for = self.params
        self._centre_only()
        return bool(self.inputs.handle_position.valid
                    and np.linalg.norm(self.inputs.handle_position.value) < self.params.centred_within_m)

    def compute(self) -> None:
        p_in = self.inputs
        out = self.outputs
        handle_ok = p_in.handle_position.valid
        if handle_ok == self.handle_lost:
            self.handle_lost = self.flags["handle_lost"] = not handle_ok
            if handle_ok:
                self.log.info("handle position back: driving resumes")
            else:
                self.log.warning("handle position stale: no force, no motion")
        if not handle_ok:  # nothing to render against, and nobody to say where to go
            for port in (out.force, out.environment_force, out.velocity_setpoint):
                port.value[:] = 0.0
                port.publish()
            return
        ranges = p_in.ranges
        if ranges.meta[0] != self.scan_seq:  # a scan not taken yet (it may have come while configuring)
            self._take_scan()
        scan_ok = ranges.valid
        if scan_ok:
            self.model.render(p_in.handle_position.value, self.twist_measured(), out.environment_force.value,
                              scan_age_s=ranges.age_ns() / 1e9)
        else:
            out.environment_force.value[:] = 0.0  # stale scan: no obstacle force to trust
        setpoint = out.velocity_setpoint.value
        self.pd.compute(p_in.handle_position.value, out.force.value, p_in.handle_velocity.value,
                        out.environment_force.value)
        handle_to_twist(p_in.handle_position.value, setpoint, self.driving)
        if self.flags["robot_held"]:
            setpoint[:] = 0.0
        if self.governor is not None and scan_ok:
            govern_cycle(setpoint, self.beams, self.stop_gap_m, setpoint, self.governor)
        self._blind_policy(not scan_ok, setpoint)
        out.force.publish()
        out.environment_force.publish()
        out.velocity_setpoint.publish()

    def pausing(self) -> None:
        self._centre_only()

    def clean(self) -> None:
        for port in ("force", "velocity_setpoint", "environment_force"):
            getattr(self.outputs, port).value[:] = 0.0
            getattr(self.outputs, port).publish()

    # -- helpers ------------------------------------------------------------------------------
    def _take_scan(self) -> None:
        """What depends on the scan alone, once per scan (15 Hz), not per cycle: filter, field, governor."""
        ranges = self.inputs.ranges
        self.scan_seq = int(ranges.meta[0])
        filtered = self.filter.apply(ranges.value)  # NaN beams are free space
        self.model.update_scan(filtered)
        if self.beams_shared:
            self.stop_gap_m = stop_gap(self.beams, self.governor)  # type: ignore[arg-type]
        elif self.governor is not None:
            self.stop_gap_m = govern_scan(filtered, self.beams, self.governor)

    def _blind_policy(self, blind: bool, twist) -> None:
        """Without a fresh scan nothing can be felt nor governed: stop, or creep (the policy says)."""
        if blind != self.blind:
            self.blind = self.flags["blind"] = blind
            if blind:
                self.log.warning("scan stale: blind, policy '%s'", self.params.blind)
            else:
                self.log.info("scan fresh again")
        if blind:
            p = self.params
            if p.blind == "stop":
                limit_blind(twist, 0.0, 0.0)
            else:
                limit_blind(twist, p.blind_speed_mps, p.blind_turn_rad_s)

    def twist_measured(self):
        platform = self.inputs.platform_velocity
        return platform.value if platform.valid else self.outputs.velocity_setpoint.value

    def _build(self) -> None:
        from hapticop.haptics.force_models import ThesisParams, make_force_model

        p = self.params
        self.pd = CentringPD(CentringParams(kp_n_per_m=p.kp_n_per_m, kd_ns_per_m=p.kd_ns_per_m,
                                            force_limit_n=p.force_limit_n))
        self.driving = DrivingParams(k1_per_s=p.k1, k2_rad_per_s_m=p.k2, dead_zone_m=p.dead_zone_m)
        self.filter = MovingAverage(window=p.moving_average)
        angles = self.filter.configure(self.inputs.angles.value if self.inputs.angles.valid
                                       else np.linspace(-0.75 * np.pi, 0.75 * np.pi, p.scan_points))
        params = {"thesis": ThesisParams, "thesis_corrected": ThesisParams}.get(p.force_model)
        model_params = params(k3_n_per_m=p.k3_n_per_m, k4_n_per_m=p.k4_n_per_m, d_max_m=p.d_max_m) if params else (
            p.braking_field if p.force_model == "braking_field" else None)
        self.model = make_force_model(p.force_model, angles, model_params)
        self.governor: GovernorParams | None = None
        self.beams_shared = False
        if p.governor:
            from hapticop.haptics.geometry import BeamGeometry, Footprint

            self.governor = governor = GovernorParams()
            # The braking field's scan points serve the governor too when both see the same body and
            # side window: the scan is then loaded and its side points selected once, not twice.
            field = getattr(self.model, "beams", None)
            self.beams_shared = field is not None and field.footprint == Footprint() and (
                (self.model.params.window_rear_m, self.model.params.window_ahead_m)  # type: ignore[attr-defined]
                == (governor.window_rear_m, governor.window_ahead_m))
            self.beams = field if self.beams_shared else BeamGeometry(angles, Footprint())
        self.scan_seq = 0  # no scan taken: the next compute takes the one in hand
        self.stop_gap_m = 0.0

    def _centre_only(self) -> None:
        """The PD alone: no obstacle force and no motion while not running."""
        out, p_in = self.outputs, self.inputs
        out.environment_force.value[:] = 0.0
        out.velocity_setpoint.value[:] = 0.0
        if hasattr(self, "pd") and p_in.handle_position.valid:
            self.pd.compute(p_in.handle_position.value, out.force.value, p_in.handle_velocity.value)
        else:
            out.force.value[:] = 0.0
        out.force.publish()
        out.environment_force.publish()
        out.velocity_setpoint.publish()
