"""Petri-net firing and the reachability analysis on small nets."""

import pytest

from hapticop.composition.description import PetriNet
from hapticop.coordination.petri import Livelock, Net
from hapticop.validation.reachability import Environment, explore


def net(**spec) -> Net:
    return Net.from_spec(PetriNet.model_validate(spec))


def test_fire_to_steady_state_follows_declaration_order():
    n = net(places={"A": None, "B": None, "C": None},
            transitions={"ab": {"in": ["A"], "out": ["B"]}, "bc": {"in": {"B": 2}, "out": ["C"]}},
            marking={"A": 3})
    marking = n.initial.copy()
    fired = n.fire_to_steady_state(marking)
    assert fired == 4 and marking.tolist() == [0, 1, 1]
    assert not n.enabled(marking).any()


def test_fire_to_steady_state_detects_livelock():
    n = net(places={"A": None}, transitions={"loop": {"in": ["A"], "out": ["A"]}}, marking={"A": 1})
    with pytest.raises(Livelock):
        n.fire_to_steady_state(n.initial.copy(), max_firings=100)


def test_explore_finds_nothing_wrong_in_a_handshake():
    # GO (an event) starts it and sends REQ out; it finishes when ACK (a level) is true.
    n = net(places={"IDLE": None, "GO": None, "WAITING": None, "REQ": None, "DONE": None, "ACK": None},
            transitions={"start": {"in": ["IDLE", "GO"], "out": ["WAITING", "REQ"]},
                         "finish": {"in": ["WAITING", "ACK"], "out": ["DONE"]}},
            marking={"IDLE": 1})
    env = Environment(tracking_sources=frozenset({"ACK"}), converting_sources=frozenset({"GO"}),
                      converting_sinks=frozenset({"REQ"}))
    analysis = explore(n, env, frozenset({"DONE"}))
    assert analysis.complete and analysis.findings == []


def test_explore_reports_a_sink_place_that_a_transition_also_waits_on():
    # REQ is emptied by its converting sink, so 'finish' may never see it: a dead marking.
    n = net(places={"IDLE": None, "REQ": None, "DONE": None},
            transitions={"start": {"in": ["IDLE"], "out": ["REQ"]}, "finish": {"in": ["REQ"], "out": ["DONE"]}},
            marking={"IDLE": 1})
    findings = explore(n, Environment(converting_sinks=frozenset({"REQ"})), frozenset({"DONE"})).findings
    assert [f.kind for f in findings] == ["dead"] and findings[0].trace == ["start", "REQ -> emit None"]


def test_explore_reports_dead_and_unbounded_and_livelock():
    dead = net(places={"A": None, "B": None, "NEVER": None},
               transitions={"t": {"in": ["A"], "out": ["B"]}, "u": {"in": ["B", "NEVER"], "out": ["A"]}},
               marking={"A": 1})
    (finding,) = explore(dead, Environment()).findings
    assert finding.kind == "dead" and finding.marking == {"B": 1} and finding.trace == ["t"]

    grow = net(places={"A": None, "B": None}, transitions={"t": {"in": ["A"], "out": ["A", "B"]}}, marking={"A": 1})
    (finding,) = explore(grow, Environment()).findings
    assert finding.kind == "unbounded" and finding.place == "B"

    spin = net(places={"A": None, "B": None},
               transitions={"ab": {"in": ["A"], "out": ["B"]}, "ba": {"in": ["B"], "out": ["A"]}},
               marking={"A": 1})
    (finding,) = explore(spin, Environment()).findings
    assert finding.kind == "livelock" and set(finding.trace) == {"ab", "ba"}


def test_explore_stops_at_the_state_limit():
    # Six tokens moving round a ring of twelve places: thousands of markings.
    ring = {f"P{i}": None for i in range(12)}
    moves = {f"t{i}": {"in": [f"P{i}"], "out": [f"P{(i + 1) % 12}"]} for i in range(12)}
    n = net(places=ring, transitions=moves, marking={f"P{i}": 1 for i in range(6)})
    analysis = explore(n, Environment(), state_limit=200)
    assert not analysis.complete and analysis.states >= 200 and analysis.findings == []


MODES = dict(  # drive while the grip (a level flag) is held, park when it is let go
    places={"DRIVE": None, "PARK": None, "GRIPPED": None},
    transitions={"park": {"in": ["DRIVE"], "out": ["PARK"], "unless": ["GRIPPED"]},
                 "drive": {"in": ["PARK", "GRIPPED"], "out": ["DRIVE", "GRIPPED"]}},
    marking={"PARK": 1})


def test_an_inhibitor_arc_fires_only_while_its_place_is_empty():
    n = net(**MODES)
    drive, park, gripped = (n.index(p) for p in ("DRIVE", "PARK", "GRIPPED"))
    marking = n.initial.copy()
    marking[gripped] = 1  # the grip is held: drive, and stay driving
    n.fire_to_steady_state(marking)
    assert marking[drive] == 1 and marking[park] == 0
    assert not n.enabled(marking).any()
    marking[gripped] = 0  # let go: park
    n.fire_to_steady_state(marking)
    assert marking[park] == 1 and marking[drive] == 0
    assert n.enabled(marking).tolist() == [False, False]


def test_explore_lets_a_tracked_flag_open_an_inhibitor_at_any_step():
    env = Environment(tracking_sources=frozenset({"GRIPPED"}))
    analysis = explore(net(**MODES), env)
    assert analysis.complete and analysis.findings == [] and analysis.states == 2


def test_explore_tests_a_kept_inhibitor_place_for_zero():
    # 'late' waits for BUSY to empty; nothing ever empties it: a dead marking
    n = net(places={"A": None, "BUSY": None, "B": None},
            transitions={"late": {"in": ["A"], "out": ["B"], "unless": ["BUSY"]}},
            marking={"A": 1, "BUSY": 1}, terminal=["B"])
    (finding,) = explore(n, Environment(), frozenset({"B"})).findings
    assert finding.kind == "dead" and finding.marking == {"A": 1, "BUSY": 1}


def test_a_transition_needing_a_flag_true_and_false_at_once_never_fires():
    n = net(places={"A": None, "F": None, "B": None},
            transitions={"never": {"in": ["A", "F"], "out": ["B"], "unless": ["F"]}}, marking={"A": 1})
    (finding,) = explore(n, Environment(tracking_sources=frozenset({"F"}))).findings
    assert finding.kind == "dead"
