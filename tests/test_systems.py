"""Every shipped composition validates clean, and the hallway one is the thesis's layout."""

import copy

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
    # the thesis's four threads, one for the simulated world, operator, Falcon and wheels before the
    # loops they answer, and one for the simulated scanner just before the LIDAR's
    assert list(threads) == ["simulators", "main", "simulation", "lidar", "fieldbus", "watchdog"]
    assert [threads[t].period for t in threads] == [1_000_000, 1_000_000, 66_666_667, 66_666_667, 1_000_000,
                                                    1_000_000]
    assert threads["fieldbus"].priority == 39 and threads["watchdog"].priority == 40
    for simulation in ("simulators", "simulation"):  # outside the real-time loops' processes
        assert threads[simulation].deploy == "process"
    # the simulated hardware below every loop (other work must not delay it, nor it a loop); the scanner's
    # ray casts at normal scheduling (a late scan is a stale scan, never a device fault)
    loops = [threads[t].priority for t in ("main", "lidar", "fieldbus", "watchdog")]
    assert threads["simulators"].priority < min(loops) and threads["simulation"].priority is None
    # the thesis's thread 0 and thread 2 carry only what a real system runs
    assert threads["main"].schedules == {0: ["mediator"], 1: ["mediator", "falcon", "haptic"]}
    assert threads["fieldbus"].schedules[1] == ["ethercat", "ropod"]
    assert all(threads[t].schedules[0] == [] for t in ("lidar", "fieldbus", "watchdog"))
    # the simulated world is not the application's to coordinate: its threads run from the start
    assert threads["simulators"].start == "auto" and threads["simulators"].schedules == {
        0: ["world", "operator", "falcon_sim", "ropod_plant"]}
    assert threads["simulation"].start == "auto" and threads["simulation"].schedules == {0: ["lidar_sim"]}
    thesis = {"mediator", "haptic", "falcon", "lidar", "ethercat", "ropod", "ethercat_watchdog"}
    assert set(composition.activities) == thesis | {"scan_field", "world", "operator", "falcon_sim", "lidar_sim",
                                                    "ropod_plant"}
    # the scan is filtered and placed in the robot frame where it arrives, not in the 1 kHz loop (docs/haptics.md)
    assert threads["lidar"].schedules[1] == ["lidar", "scan_field"]
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


# -- the same application on the real devices -------------------------------------------------------
# What a device block's driver brings with it: the only parameters the hardware file may set otherwise.
DRIVER_KEYS = {"driver", "simulator", "firmware", "firmware_sha256", "usb_backend", "device_index", "host", "port",
               "interface"}


def _without_simulation(tree: dict) -> dict:
    """A composition with its simulation taken out, by rule: the activities whose block simulates, their
    places in schedules, a thread left with nothing to run, the streams they write and their ends of the
    streams they read, the flag-map entries of their flags, a place left unbound (always empty, so a
    transition that consumes from it is dead and goes too; one that marks it stops doing so), and the
    device blocks' driver parameters."""
    from hapticop.blocks.registry import resolve

    tree = copy.deepcopy(tree)
    simulated = {name for name, spec in tree["activities"].items() if resolve(spec["block"]).simulator}
    for name in simulated:
        del tree["activities"][name]
    for name, thread in list(tree["threads"].items()):
        schedules = {sid: [a for a in members if a not in simulated] for sid, members in thread["schedules"].items()}
        if any(set(members) & simulated for members in thread["schedules"].values()) and not any(schedules.values()):
            del tree["threads"][name]
        else:
            thread["schedules"] = schedules
    for name, stream in list(tree["streams"].items()):
        readers = stream["to"] if isinstance(stream["to"], list) else [stream["to"]]
        stream["to"] = [r for r in readers if r.split(".")[0] not in simulated]
        if stream["from"].split(".")[0] in simulated or not stream["to"]:
            del tree["streams"][name]
    bound = set()
    for fmap in tree["coordination"]["flag_maps"].values():
        for kind in ("converting_sources", "tracking_sources", "converting_sinks", "tracking_sinks"):
            entries = fmap.get(kind, {})
            for flag in [f for f in entries if f.split(".")[0] in simulated]:
                del entries[flag]
            bound |= {(fmap["net"], place) for place in entries.values()}
    for net_name, net in tree["coordination"]["nets"].items():
        unbound = {p for p in net["places"] if (net_name, p) not in bound and not net.get("marking", {}).get(p)
                   and p not in net.get("terminal", []) and not any(p in t["out"] for t in net["transitions"].values())}
        for place in unbound:
            del net["places"][place]
        for name, transition in list(net["transitions"].items()):
            if set(transition["in"]) & unbound:
                del net["transitions"][name]
    for spec in tree["activities"].values():
        for key in DRIVER_KEYS & set(spec.get("params") or {}):
            del spec["params"][key]
    for key in ("name", "doc"):
        tree.pop(key, None)
    return tree


def _expanded(path) -> dict:
    """The file as `hapticop expand` prints it: its standard coordination written out as nets and flag maps."""
    from hapticop.composition.standard import expanded_tree
    from hapticop.composition.yamlsource import plain

    validated = validate_path(path)
    assert validated.report.ok
    return plain(expanded_tree(validated.source.tree, validated.graph.loaded.expansion))


def test_the_hardware_file_is_the_hallway_without_its_simulation():
    """Composing the hallway for the real Falcon, TiM561 and ropod is taking the simulation out and
    changing the device blocks' drivers, nothing else (compared as the nets the runtime gets)."""
    hallway = _expanded(SYSTEMS / "hallway.yaml")
    hardware = _expanded(SYSTEMS / "hardware.yaml")
    assert _without_simulation(hardware) == _without_simulation(hallway)
    drivers = {name: spec["params"]["driver"] for name, spec in hardware["activities"].items()
               if "driver" in (spec.get("params") or {})}
    assert drivers == {"falcon": "usb", "lidar": "tcp", "ethercat": "pysoem"}
    assert not any(resolve_simulates(spec["block"]) for spec in hardware["activities"].values())


def resolve_simulates(block: str) -> bool:
    from hapticop.blocks.registry import resolve

    return resolve(block).simulator


def test_taking_the_simulation_out_is_not_a_no_op():
    """The rule above does remove what it says (so the comparison cannot pass by accident)."""
    hallway = _without_simulation(_expanded(SYSTEMS / "hallway.yaml"))
    assert {"world", "operator", "falcon_sim", "lidar_sim", "ropod_plant"}.isdisjoint(hallway["activities"])
    assert "simulation" not in hallway["threads"] and "pose_in_hallway" not in hallway["streams"]
    mediator = hallway["coordination"]["nets"]["mediator"]
    assert "FINISHED" not in mediator["places"] and "finished" not in mediator["transitions"]
    assert "HAPTIC_RUNNING" in mediator["places"]  # still bound to haptic.lcsm.running
    assert "driver" not in hallway["activities"]["falcon"]["params"]
