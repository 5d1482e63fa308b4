"""The generic G_I_LL_LPF controller bank against reference.json (docs/devices/ropod.md §6)."""

from __future__ import annotations

import numpy as np
import pytest

from hapticop.devices.ropod.controller_params import (
    ROPOD2019_PLATFORM_THETA,
    ROPOD2019_PLATFORM_XY,
    THESIS_PLATFORM_THETA,
    THESIS_PLATFORM_XY,
    THESIS_WHEEL,
    LinearControllerParams,
)
from hapticop.devices.ropod.linear_bank import ControllerBank
from hapticop.testing import allocation_stats

from .test_ropod_data import load

TS = 0.001
REL = 1e-9  # reference.json's controller_rel; its values are printed to 12 decimals
CASES = load("reference")["generic_controller"]


def _inputs(name: str, case: dict, samples: int) -> tuple[np.ndarray, np.ndarray]:
    """The error sequence and reset sequence each case describes in words."""
    k = np.arange(samples)
    reset = np.zeros(samples, bool)
    if "saturation" in name:
        hi, lo = (2.0, -0.4) if "xy" in name else (200.0, -40.0)
        assert f"e[k]={hi}" in case["input"] and f"e[k]={lo}" in case["input"]
        e = np.where(k < 300, hi, np.where(k < 600, lo, 0.0))
    elif "reset" in name:
        assert "10<=k<15" in case["input"]
        e = np.full(samples, 0.1)
        reset[10:15] = True
    else:
        e = np.full(samples, case["step_amplitude"])
    return e, reset


def _run(name: str, samples: int = 1000) -> dict[str, np.ndarray]:
    case = CASES[name]
    bank = ControllerBank(LinearControllerParams.from_mapping(case["params"]), TS, n=1)
    e, reset = _inputs(name, case, samples)
    y, out = {k: np.zeros(samples) for k in ("y", "pi", "ll")}, np.zeros(1)
    clamped = np.zeros(samples, bool)
    for k in range(samples):
        bank.step(e[k:k + 1], out, reset[k:k + 1])
        y["y"][k], y["pi"][k], y["ll"][k], clamped[k] = out[0], bank.y_pi[0], bank.y_leadlag[0], bank.clamped[0]
    y["clamped"] = clamped
    return y


def _close(actual, expected) -> None:
    expected = np.asarray(expected, float)
    np.testing.assert_allclose(actual, expected, rtol=REL, atol=REL * max(1.0, np.abs(expected).max()))


@pytest.mark.parametrize("name", sorted(CASES))
def test_outputs_match_the_reference(name):
    case, run = CASES[name], _run(name)
    if "y_first20" in case:
        _close(run["y"][:20], case["y_first20"])
    if "y_first40" in case:
        _close(run["y"][:40], case["y_first40"])
    for key, value in case.get("y_at", {}).items():
        _close(run["y"][int(key.removeprefix("k="))], value)
    if "y_k300_to_k319" in case:
        _close(run["y"][300:320], case["y_k300_to_k319"])
    if "clamped_first20" in case:
        assert run["clamped"][:20].tolist() == case["clamped_first20"]


@pytest.mark.parametrize("name", sorted(n for n in CASES if "stage_first20" in CASES[n]))
def test_every_stage_matches_the_reference(name):
    stages, run = CASES[name]["stage_first20"], _run(name, 20)
    _close(run["pi"], stages["after_PI_sat"])
    _close(run["ll"], stages["after_leadlag"])
    _close(run["y"], stages["after_lpf"])


def test_worked_values_of_the_notes():
    """§6.4: thesis x/y at e = 0.1 and the wheel controller at 1 rad/s."""
    xy = _run("thesis_platform_xy", 5)
    np.testing.assert_allclose(xy["y"][:5], [2.39245, 6.03724, 7.94691, 8.95105, 9.48261], atol=6e-6)
    np.testing.assert_allclose(xy["pi"][:2], [10.00785, 10.02356], atol=6e-6)
    wheel = _run("thesis_wheel", 4)
    np.testing.assert_allclose(wheel["y"], [0.033112, 0.088742, 0.126158, 0.150495], atol=6e-7)
    assert wheel["ll"][0] == pytest.approx(0.2439, abs=1e-4)


def test_saturation_limits_the_pi_stage_not_the_output():
    """The wheel PI is clipped at 7 Nm; lead-lag and low-pass then peak near 25 Nm (§6.1)."""
    run = _run("thesis_wheel_saturation", 300)
    assert np.abs(run["pi"]).max() == pytest.approx(7.0)
    assert 20.0 < run["y"].max() < 30.0
    xy = _run("thesis_platform_xy_saturation", 600)
    assert run["clamped"].sum() == 0  # no integrator in the wheel controller: nothing to wind up
    assert xy["clamped"][:300].all() and np.abs(xy["pi"]).max() == pytest.approx(100.0)


def test_parameter_sets_are_the_references():
    for name, params in [("thesis_platform_xy", THESIS_PLATFORM_XY), ("thesis_platform_theta", THESIS_PLATFORM_THETA),
                         ("thesis_wheel", THESIS_WHEEL), ("ropod2019_platform_xy", ROPOD2019_PLATFORM_XY),
                         ("ropod2019_platform_theta", ROPOD2019_PLATFORM_THETA)]:
        assert LinearControllerParams.from_mapping(CASES[name]["params"]) == params


def test_a_bank_steps_its_channels_independently():
    """All reference cases at once, one channel each, give each case's own outputs."""
    names = sorted(CASES)
    params = [LinearControllerParams.from_mapping(CASES[n]["params"]) for n in names]
    bank = ControllerBank(params, TS)
    assert bank.n == len(names)
    inputs = [_inputs(n, CASES[n], 700) for n in names]
    e = np.array([i[0] for i in inputs]).T.copy()
    reset = np.array([i[1] for i in inputs]).T.copy()
    y, out = np.zeros((700, len(names))), np.zeros(len(names))
    for k in range(700):
        bank.step(e[k], out, reset[k])
        y[k] = out
    for j, name in enumerate(names):
        np.testing.assert_array_equal(y[:, j], _run(name, 700)["y"])


def test_reset_returns_to_the_initial_state():
    bank = ControllerBank(THESIS_PLATFORM_XY, TS, n=3)
    out, first = np.zeros(3), np.zeros(3)
    e = np.array([0.1, -2.0, 0.5])
    bank.step(e, first)
    for _ in range(50):
        bank.step(e, out)
    bank.reset()
    bank.step(e, out)
    np.testing.assert_array_equal(out, first)


def test_invalid_parameters_are_refused():
    with pytest.raises(ValueError):
        ControllerBank(LinearControllerParams(1.0, 0.0, 0.0, 1.0, 1.0, 1.0), TS)
    with pytest.raises(ValueError):
        ControllerBank(THESIS_WHEEL, 0.0)


def test_step_allocates_nothing():
    """Nothing retained and no temporaries beyond numpy's own call overhead (a bare np.clip peaks at ~5 KiB)."""
    bank = ControllerBank([THESIS_PLATFORM_XY] * 3 + [THESIS_WHEEL] * 8, TS)
    e, out, reset = np.linspace(-3, 3, 11), np.zeros(11), np.zeros(11, bool)
    retained, peak = allocation_stats(lambda: bank.step(e, out, reset), 2000)
    assert retained < 256 and peak < 1024
