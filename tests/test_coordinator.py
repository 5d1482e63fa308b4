"""The mediator's coordination step: the four flag-map kinds and firing to a steady state."""

import numpy as np
import pytest

from hapticop.composition.description import Coordination
from hapticop.coordination.coordinator import Coordinator
from hapticop.coordination.petri import Livelock

FLAGS = ["a.event", "a.level", "b.request", "b.ready"]


def coordinator(net: dict, flag_map: dict):
    coordination = Coordination.model_validate({"nets": {"n": net}, "flag_maps": {"m": {"net": "n", **flag_map}}})
    flags = np.zeros(len(FLAGS), np.uint8)
    return Coordinator(coordination, flags, {f: i for i, f in enumerate(FLAGS)}), flags


def f(flags, name):
    return int(flags[FLAGS.index(name)])


def set_flag(flags, name, value=1):
    flags[FLAGS.index(name)] = value


NET = {
    "places": {"IDLE": None, "EVENT": None, "LEVEL": None, "REQ": None, "READY": None},
    "transitions": {"go": {"in": ["IDLE", "EVENT", "LEVEL"], "out": ["REQ", "READY"]}},
    "marking": {"IDLE": 1},
}
MAP = {
    "converting_sources": {"a.event": "EVENT"},
    "tracking_sources": {"a.level": "LEVEL"},
    "converting_sinks": {"b.request": "REQ"},
    "tracking_sinks": {"b.ready": "READY"},
}


def test_the_four_kinds_in_order():
    c, flags = coordinator(NET, MAP)
    assert c.step() and c.markings()["n"] == {"IDLE": 1}
    set_flag(flags, "a.event")
    c.step()
    assert f(flags, "a.event") == 0  # converted: consumed once
    assert c.markings()["n"] == {"IDLE": 1, "EVENT": 1}  # waiting for the level
    set_flag(flags, "a.level")
    c.step()
    # fired; the converting sink took its token and set the flag; the tracking sink mirrors READY
    assert c.markings()["n"] == {"READY": 1}
    assert f(flags, "b.request") == 1 and f(flags, "b.ready") == 1
    set_flag(flags, "b.request", 0)  # the reader consumed the request
    set_flag(flags, "a.level", 0)
    c.step()
    assert f(flags, "b.request") == 0 and f(flags, "b.ready") == 1


def test_a_tracking_source_mirrors_the_level_both_ways():
    net = {"places": {"L": None}, "transitions": {}, "marking": {}}
    c, flags = coordinator(net, {"tracking_sources": {"a.level": "L"}, "tracking_sinks": {"b.ready": "L"}})
    for level in (1, 0, 1):
        set_flag(flags, "a.level", level)
        c.step()
        assert c.markings()["n"].get("L", 0) == level and f(flags, "b.ready") == level


def test_unchanged_flags_cost_no_step():
    c, flags = coordinator(NET, MAP)
    assert c.step() is True
    assert c.step() is False  # nothing changed since
    set_flag(flags, "a.event")
    assert c.step() is True


def test_converting_sink_emits_one_token_per_step():
    net = {"places": {"A": None, "OUT": None}, "transitions": {"t": {"in": {"A": 1}, "out": {"OUT": 1}}},
           "marking": {"A": 3}}
    c, flags = coordinator(net, {"converting_sinks": {"b.request": "OUT"}})
    emitted = 0
    for _ in range(5):
        c.step()
        emitted += f(flags, "b.request")
        set_flag(flags, "b.request", 0)
    assert emitted == 3


def test_firing_to_steady_state_and_livelock():
    net = {"places": {"A": None, "B": None, "C": None},
           "transitions": {"ab": {"in": ["A"], "out": ["B"]}, "bc": {"in": {"B": 2}, "out": ["C"]}},
           "marking": {"A": 4}}
    c, _ = coordinator(net, {})
    c.step()
    assert c.markings()["n"] == {"C": 2}
    spin = {"places": {"A": None}, "transitions": {"t": {"in": ["A"], "out": ["A"]}}, "marking": {"A": 1}}
    c, _ = coordinator(spin, {})
    with pytest.raises(Livelock):
        c.step()
