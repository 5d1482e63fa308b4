"""The ropod's generic linear controller's parameter set, and the sets the thesis and the ropod
used: kept apart from the compiled bank (a compiled module's classes have no source to read their
field docstrings from)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import fields
from typing import Annotated, Any

from annotated_types import Ge, Gt

from hapticop.parameters import parameters

__all__ = [
    "LinearControllerParams", "THESIS_PLATFORM_XY", "THESIS_PLATFORM_THETA", "THESIS_WHEEL",
    "ROPOD2019_PLATFORM_XY", "ROPOD2019_PLATFORM_THETA",
    "HOSPITAL2018_PLATFORM_XY", "HOSPITAL2018_PLATFORM_THETA", "ROPOD_PIVOT_DAMPING",
]


@parameters
class LinearControllerParams:
    """One generic controller (gain, PI, lead-lag, low-pass) in the thesis's / ropod's names; frequencies in Hz."""

    p_gain: float
    """K, the gain: N/(m/s) or Nm/(rad/s) on the platform, Nm/(rad/s) on a wheel."""
    i_fhz: Annotated[float, Ge(0)]
    """The PI's corner frequency; 0 makes the PI a pure gain."""
    ll_zero_fhz: Annotated[float, Gt(0)]
    """The lead-lag's zero; equal to its pole, there is no lead-lag."""
    ll_pole_fhz: Annotated[float, Gt(0)]
    """The lead-lag's pole."""
    lpf_fhz: Annotated[float, Gt(0)]
    """The low-pass's cut-off."""
    i_saturation: Annotated[float, Gt(0)]
    """Clamps the PI's output (the thesis's "I saturation", ropod's `i_sat`), in the gain's output unit."""

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> LinearControllerParams:
        """Accept both the block's `i_saturation` and reference.json's `i_sat`."""
        data = {k: v for k, v in values.items() if k in {f.name for f in fields(cls)}}
        if "i_sat" in values and "i_saturation" not in data:
            data["i_saturation"] = values["i_sat"]
        return cls(**data)


# Parameter sets of docs/devices/ropod.md §6.3 (platform K in N/(m/s) or Nm/(rad/s), wheel K in Nm/(rad/s)).
THESIS_PLATFORM_XY = LinearControllerParams(100.0, 0.25, 20.0, 20.0, 100.0, 100.0)
THESIS_PLATFORM_THETA = LinearControllerParams(755.0, 0.3, 20.0, 20.0, 100.0, 100.0)
THESIS_WHEEL = LinearControllerParams(0.05, 0.0, 2.0, 10.0, 50.0, 7.0)
ROPOD2019_PLATFORM_XY = LinearControllerParams(200.0, 0.25, 20.0, 20.0, 100.0, 500.0)
ROPOD2019_PLATFORM_THETA = LinearControllerParams(150.0, 0.3, 20.0, 20.0, 100.0, 250.0)
HOSPITAL2018_PLATFORM_XY = LinearControllerParams(150.0, 0.25, 20.0, 20.0, 100.0, 500.0)
HOSPITAL2018_PLATFORM_THETA = LinearControllerParams(100.0, 0.3, 20.0, 20.0, 100.0, 250.0)
ROPOD_PIVOT_DAMPING = LinearControllerParams(0.1, 0.0, 2.0, 2.0, 50.0, 7.0)
