"""Every shipped composition validates clean, and the hallway one is the thesis's layout."""

import pytest

from hapticop.validation import validate_path

from .conftest import SYSTEMS


@pytest.mark.parametrize("path", sorted(SYSTEMS.glob("*.yaml")), ids=lambda p: p.name)
def test_system_validates_clean(path):
    report = validate_path(path).report
    assert report.diagnostics == [], "\n".join(d.to_text() for d in report.diagnostics)


def test_hallway_is_the_thesis_layout():
    composition = validate_path(SYSTEMS / "hallway.yaml").composition
    threads = composition.threads
    # the thesis's four threads, and one for the simulated scanner just before the LIDAR's
    assert list(threads) == ["main", "simulation", "lidar", "fieldbus", "watchdog"]
    assert [threads[t].period for t in threads] == [1_000_000, 66_666_667, 66_666_667, 1_000_000, 1_000_000]
    assert threads["fieldbus"].priority == 39 and threads["watchdog"].priority == 40
    assert threads["simulation"].priority is None and threads["simulation"].deploy == "process"
    # the thesis's thread 0, plus the simulation that stands in for the real world: the world, the
    # operator and the simulated Falcon, which answers just before the Falcon reads
    assert threads["main"].schedules == {
        0: ["mediator"], 1: ["mediator", "world", "operator", "falcon_sim", "falcon", "haptic"]}
    assert all(threads[t].schedules[0] == [] for t in ("simulation", "lidar", "fieldbus", "watchdog"))
    thesis = {"mediator", "haptic", "falcon", "lidar", "ethercat", "ropod", "ethercat_watchdog"}
    assert set(composition.activities) == thesis | {"world", "operator", "falcon_sim", "lidar_sim", "ropod_plant"}
    assert composition.activities["falcon"].params["simulator"] == "falcon_sim"
    haptic = composition.activities["haptic"].params
    centring, driving = haptic["centring"], haptic["driving"]
    assert (centring["kp_n_per_m"], centring["kd_ns_per_m"], driving["k1_per_s"], driving["k2_rad_per_s_m"]) == (
        55.0, 0.2, 28.0, 10.0)
    assert (driving["dead_zone_m"], centring["force_limit_n"]) == (0.005, 10.0)
    lidar = composition.activities["lidar"].params
    assert (lidar["points"], lidar["scan_rate_hz"]) == (811, 15.0)
    ropod = composition.activities["ropod"].params
    assert ropod["platform_theta"]["p_gain"] == 755 and ropod["wheel"]["i_saturation"] == 7
    assert set(composition.coordination.nets) == {"mediator", "thread_lcsm", "thread_scheduler"}
