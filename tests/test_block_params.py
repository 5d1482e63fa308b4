"""The haptic and ropod controllers' parameters are their libraries' parameter sets, nested as they are."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import pytest
from pydantic import ValidationError

from hapticop.blocks.haptic import HapticController, HapticControllerParams
from hapticop.blocks.ropod import RopodController, RopodControllerParams
from hapticop.devices.ropod.velocity_controller import PlatformControllerParams
from hapticop.haptics.force_models import BrakingFieldParams, ThesisParams
from hapticop.haptics.governor import BlindPolicy, GovernorParams
from hapticop.haptics.handle import CentringParams, DrivingParams
from hapticop.haptics.scan_filter import MovingMedianParams


def test_the_haptic_controllers_defaults_are_the_libraries():
    p = HapticControllerParams()
    assert (p.centring, p.driving, p.blind) == (CentringParams(), DrivingParams(), BlindPolicy())
    assert p.force_model == BrakingFieldParams() and p.scan_filter is None
    assert p.governor is None  # the governor is chosen, not implied


def test_nested_parameters_become_the_libraries_dataclasses():
    p = HapticControllerParams.model_validate({
        "driving": {"k1_per_s": 30.0},
        "force_model": {"kind": "thesis_corrected", "d_max_m": 2.5},
        "governor": {},
        "scan_filter": {"kind": "moving_median", "window": 7},
    })
    assert p.driving == DrivingParams(k1_per_s=30.0)
    assert p.force_model == ThesisParams(d_max_m=2.5, kind="thesis_corrected")
    assert p.governor == GovernorParams() and p.scan_filter == MovingMedianParams(window=7)
    for bad in ({"centring": {"kp": 55.0}}, {"force_model": {"kind": "none", "k3_n_per_m": 1.0}},
                {"scan_filter": {"kind": "moving_average", "window": 2, "min_valid": 3}},
                {"scan_filter": {"kind": "moving_median", "window": 4}}, {"blind": {"policy": "crawl"}}):
        with pytest.raises(ValidationError):
            HapticControllerParams.model_validate(bad)


def test_the_schema_carries_the_libraries_descriptions():
    schema = HapticControllerParams.model_json_schema()
    centring = schema["$defs"]["CentringParams"]["properties"]["kp_n_per_m"]
    assert centring["description"] == "Spring to the origin, N/m." and centring["default"] == 55.0
    field = schema["$defs"]["BrakingFieldParams"]
    assert field["additionalProperties"] is False and "dist2" in field["properties"]["stop_distance_m"]["description"]
    wheel = RopodControllerParams.model_json_schema()["$defs"]["LinearControllerParams"]["properties"]
    assert "corner frequency" in wheel["i_fhz"]["description"]


def test_live_patch_classes_name_parameters():
    for block in (HapticController, RopodController):
        fields = set(block.Params.model_fields)
        assert block.capability_params <= fields and block.running_params <= fields
    # A gain patch must never take the haptic loop out of running (issue 15): every law retunes live.
    assert {"blind", "centring", "driving", "force_model", "governor", "scan_filter"} <= HapticController.running_params
    assert not HapticController.capability_params
    assert {"platform_xy", "platform_theta", "wheel"} <= RopodController.running_params


def test_the_ropod_controllers_defaults_are_the_libraries():
    p, library = RopodControllerParams(), PlatformControllerParams()
    assert all(getattr(p, name) == getattr(library, name) for name in RopodControllerParams.model_fields)


def _ropod_block(params: RopodControllerParams) -> RopodController:
    """The block alone: its hooks need only its parameters."""
    context = SimpleNamespace(name="ropod", params=params, inputs=None, outputs=None, flags=None, clock=None,
                              log=None, rng=None, run_dir=None)
    return RopodController(context)  # type: ignore[arg-type]


def test_a_gain_patch_takes_effect_in_capability_configuration():
    block = _ropod_block(RopodControllerParams())
    block.configure_resources()
    block.configure_capabilities()
    same = block.controller
    block.configure_capabilities()  # a restart with the same gains: the same controller, reset
    assert block.controller is same
    wheel = dataclasses.replace(RopodControllerParams().wheel, p_gain=0.08)
    block.params = RopodControllerParams(wheel=wheel)  # what a live patch does before capability configuration
    block.configure_capabilities()
    assert block.controller.params.wheel == wheel
    assert block.controller is not same
    assert block.controller.params.platform_xy == PlatformControllerParams().platform_xy
