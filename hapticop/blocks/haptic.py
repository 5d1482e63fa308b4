"""The haptic controller: handle displacement to robot velocity, obstacles to force.

It holds the handle at its origin with a PD, maps displacement to velocity setpoints with the
car-driving metaphor and adds the environmental force of the chosen model, everything limited
per axis. Its parameters are the control laws' own (``hapticop.haptics``), nested one set per law:
their defaults, units and descriptions are written there once.
"""

from __future__ import annotations

from typing import Annotated

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Display, Interface, Params, Port, RateRange
from hapticop.haptics.force_models import BrakingFieldParams, ForceModelParams, make_force_model
from hapticop.haptics.geometry import BeamGeometry
from hapticop.haptics.governor import (
    BlindPolicy,
    GovernorParams,
    govern_cycle,
    govern_field,
    govern_scan,
    limit_blind_by,
    stop_gap,
)
from hapticop.haptics.handle import (
    CentringParams,
    CentringPD,
    CorrectionFeel,
    CorrectionFeelParams,
    DrivingParams,
    handle_to_twist,
)
from hapticop.haptics.scan_field import ANGLE, ROWS
from hapticop.haptics.scan_filter import MovingAverageParams, ScanFilterParams, make_scan_filter


class HapticControllerParams(Params):
    """One parameter set per control law, each the library's own (``hapticop.haptics``)."""

    centring: CentringParams = Field(default_factory=CentringParams)
    driving: DrivingParams = Field(default_factory=DrivingParams)
    force_model: ForceModelParams = Field(
        default_factory=BrakingFieldParams, discriminator="kind",
        description="the environmental force; 'kind' chooses the model (none, thesis, thesis_corrected, "
        "braking_field) and the other keys are that model's parameters")
    governor: GovernorParams | None = Field(
        None, description="the robot-side speed governor S1 ({} for its defaults); null: none")
    blind: BlindPolicy = Field(default_factory=BlindPolicy)
    scan_filter: Annotated[ScanFilterParams, Field(discriminator="kind")] | None = Field(
        None, description="the per-beam filter of a raw scan on the ranges input: 'kind' moving_average or "
        "moving_median; null: the 3-beam moving average. With the scan_field input connected instead, the "
        "scan_field activity declares it (set here, validation refuses it)")
    correction_feel: CorrectionFeelParams | None = Field(
        None, description="shared control: render the robot's correction of the command (the velocity_correction "
        "input) as part of the environmental force ({} for its defaults); null: not felt")
    scan_points: int = Field(811, ge=2, le=10_000, description="points per scan (the ranges and angles ports)")
    centred_within_m: float = Field(0.005, gt=0, description="capability configuration ends with the handle this close")


class HapticController(Block):
    Params = HapticControllerParams
    flags_read = {"resources_ready": "the Falcon, LIDAR and ropod controller are running",
                  "robot_held": "the robot is held still (a wheel is not in OP): command no motion"}
    flags_written = {"blind": "the scan is stale: the blind policy limits the robot",
                     "handle_lost": "the handle position is stale (Falcon frames stopped): no force, no motion"}
    awaits = frozenset({"resources_ready"})
    optional_flags = frozenset({"robot_held"})  # only a composition with a fieldbus watchdog binds it
    period_params = frozenset({"centring.period_s", "force_model.period_s"})

    @classmethod
    def displays(cls, params: HapticControllerParams) -> tuple[Display, ...]:
        """The force on the handle, as an arrow over the robot."""
        return (Display("force_arrow", {"force": "force"}),)

    # Every law retunes between two cycles (`retune`): a live gain change never stops the robot.
    running_params = frozenset({"blind", "centring", "driving", "force_model", "governor", "scan_filter",
                                "centred_within_m", "correction_feel"})

    @classmethod
    def interface(cls, params: HapticControllerParams) -> Interface:
        n = (params.scan_points,)
        return Interface(
            inputs={
                "handle_position": Port("float64", (3,), "m"),
                "handle_velocity": Port("float64", (3,), "m/s"),
                "ranges": Port("float32", n, "m", "the raw scan, filtered and rendered in this loop "
                               "(unconnected: the scan_field input)", required=False),
                "angles": Port("float32", n, "rad", required=False),
                "scan_field": Port("float64", (ROWS, params.scan_points), "m, rad, m, m",
                                   "the scan rendered beside the loop by a scan_field block (filtered ranges, "
                                   "angles, robot-frame points); once fed, it replaces ranges and angles",
                                   required=False),
                "platform_velocity": Port("float64", (3,), "m/s, m/s, rad/s", required=False),
                "predicted_travel": Port("float64", (3,), "m, m, rad", "the robot's motion since the scan, "
                                         "predicted (a pose_predictor's travel): the scan is rendered from "
                                         "there (model-mediated); unconnected: measured twist × scan age",
                                         required=False),
                "velocity_correction": Port("float64", (3,), "m/s, m/s, rad/s", "what a robot-side safety layer "
                                            "changed of the setpoint (executed minus commanded)", required=False),
            },
            outputs={
                "force": Port("float64", (3,), "N", "force for the Falcon"),
                "velocity_setpoint": Port("float64", (3,), "m/s, m/s, rad/s", "platform twist [vx, vy, wz]"),
                "environment_force": Port("float64", (3,), "N", "the obstacle part of the force"),
            },
            flags_read=dict(cls.flags_read),
            flags_written=dict(cls.flags_written),
            rate=RateRange(500.0, 2000.0, "the haptic loop renders stiff forces only near 1 kHz"),
            one_of=(("ranges", "scan_field"),),  # the scan, raw or rendered beside the loop
            input_params={"scan_filter": "ranges"},  # a rendered scan comes filtered by its own block's
        )

    # -- life cycle -------------------------------------------------------------------------
    def create(self) -> None:
        self.handle_lost = self.blind = False  # what the flags of the same names last said

    def configure_resources(self) -> bool:
        """Wait until the Falcon, the LIDAR and the ropod controller run (the mediator says so)."""
        return self.flags["resources_ready"]

    def configure_capabilities(self) -> bool:
        """Build the control laws, then, the first time only, hold the handle at its origin before
        commanding motion (a later re-configuration finds the handle in the operator's hand)."""
        if getattr(self, "built_for", None) is not self.params:  # first time, or re-configured
            self._build()
            self.built_for = self.params
        self._centre_only()
        if getattr(self, "centred_once", False):  # a re-configuration while the operator holds the handle:
            return True  # waiting for a re-centred handle could hold the application for ever
        handle = self.inputs.handle_position
        if not handle.valid:
            self.context.waiting_for("the handle's position (no Falcon frames yet)")
            return False
        off_centre = float(np.linalg.norm(handle.value))
        if off_centre >= self.params.centred_within_m:
            self.context.waiting_for(f"the handle within {self.params.centred_within_m * 1e3:g} mm of its "
                                     f"centre before commanding motion (it is {off_centre * 1e3:.0f} mm off)")
            return False
        self.context.waiting_for(None)
        self.centred_once = True
        return True

    def retune(self, changed: frozenset[str]) -> None:
        """A gain, limit or model changed while running: the next cycle uses it, with no re-centring.
        The PD keeps its last position (its velocity estimate does not jump); a new filter or force
        model takes the scan in hand at once."""
        p = self.params
        if "centring" in changed:
            self.pd.params = p.centring
        self.driving = p.driving
        if "correction_feel" in changed:
            self._build_feel()
        if changed & {"scan_filter", "force_model", "governor"}:
            self._build_scan_laws()
        self.built_for = p

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
        if not self.use_field and p_in.scan_field.meta[0]:  # the first rendered scan: the laws take its angles
            self._build_scan_laws()
        ranges = p_in.scan_field if self.use_field else p_in.ranges
        if ranges.meta[0] != self.scan_seq:  # a scan not taken yet (it may have come while configuring)
            self._take_scan()
        scan_ok = ranges.valid
        travel = p_in.predicted_travel.value if p_in.predicted_travel.valid else None
        twist = self.twist_measured()
        scan_age_s = ranges.age_ns() / 1e9
        if scan_ok:
            self.model.render(p_in.handle_position.value, twist, out.environment_force.value, scan_age_s=scan_age_s,
                              travel=travel)
        else:
            out.environment_force.value[:] = 0.0  # stale scan: no obstacle force to trust
        correction = p_in.velocity_correction
        if self.feel is not None and correction.valid:  # the robot disagrees: the operator feels by how much
            self.feel.add(correction.value, out.environment_force.value)
        setpoint = out.velocity_setpoint.value
        self.pd.compute(p_in.handle_position.value, out.force.value, p_in.handle_velocity.value,
                        out.environment_force.value)
        handle_to_twist(p_in.handle_position.value, setpoint, self.driving)
        if self.flags["robot_held"]:
            setpoint[:] = 0.0
        if self.governor is not None and scan_ok:
            # The gap now, not at the scan: moved on by what the robot has driven since (§7.4); on the scan's
            # gap alone the limit fell in 15 Hz steps, each a jolt the operator felt. Behind a link the robot's
            # own governor decides, and this one, on the scan seen from the predicted pose, is the model of it
            # that keeps the commands sent (and so the prediction) what the robot does.
            gap = (self.stop_gap_m - float(travel[0]) if travel is not None
                   else self.stop_gap_m - max(float(twist[0]), 0.0) * scan_age_s)
            govern_cycle(setpoint, self.beams, gap, setpoint, self.governor)
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
        """What depends on the scan alone, once per scan (15 Hz), not per cycle: filter, field, governor.
        A scan_field input comes filtered and as points: only the model's and the governor's choices
        of points are left to do here (docs/haptics.md)."""
        if self.use_field:
            field = self.inputs.scan_field
            self.scan_seq = int(field.meta[0])
            self.model.update_field(field.value)
            if self.beams_shared:
                self.stop_gap_m = stop_gap(self.beams, self.governor)  # type: ignore[arg-type]
            elif self.governor is not None:
                self.stop_gap_m = govern_field(field.value, self.beams, self.governor)
            return
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
                self.log.warning("scan stale: blind, policy '%s'", self.params.blind.policy)
            else:
                self.log.info("scan fresh again")
        if blind:
            limit_blind_by(twist, self.params.blind)

    def twist_measured(self):
        platform = self.inputs.platform_velocity
        return platform.value if platform.valid else self.outputs.velocity_setpoint.value

    def _build(self) -> None:
        p = self.params
        self.pd = CentringPD(p.centring)
        self.driving = p.driving
        self._build_scan_laws()
        self._build_feel()

    def _build_feel(self) -> None:
        feel = self.params.correction_feel
        self.feel = None if feel is None else CorrectionFeel(feel, (self.context.period_ns or 1_000_000) / 1e9)

    def _build_scan_laws(self) -> None:
        """The scan filter, the force model and the governor: all hang on the scan's angles."""
        p = self.params
        field = self.inputs.scan_field
        self.use_field = bool(field.meta[0])  # a scan_field block feeds it: its scans come rendered
        self.filter = make_scan_filter(p.scan_filter or MovingAverageParams())
        if self.use_field:  # the field's filtered beams, padded to scan_points with beams that see nothing
            angles = field.value[ANGLE].copy()
        else:
            angles = self.filter.configure(self.inputs.angles.value if self.inputs.angles.valid
                                           else np.linspace(-0.75 * np.pi, 0.75 * np.pi, p.scan_points))
        self.model = make_force_model(p.force_model, angles)
        self.governor = governor = p.governor
        # The braking field's scan points serve the governor too when both select the same side
        # window: the scan is then loaded and its side points selected once, not twice.
        field = getattr(self.model, "beams", None)
        self.beams_shared = governor is not None and field is not None and (
            (p.force_model.window_rear_m, p.force_model.window_ahead_m)  # type: ignore[union-attr]
            == (governor.window_rear_m, governor.window_ahead_m))
        if governor is not None:
            self.beams = field if self.beams_shared else BeamGeometry(angles)
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
