"""The loader never crashes: any text either loads or is reported as located errors."""

from __future__ import annotations

import io

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from ruamel.yaml import YAML

from hapticop.composition.diagnostics import Report
from hapticop.validation import validate_text

FIELDS = ["version", "threads", "activities", "streams", "coordination", "period", "priority", "deploy",
          "schedules", "block", "params", "from", "to", "policy", "nets", "flag_maps", "places", "transitions",
          "in", "out", "marking", "terminal", "net", "tracking_sources", "converting_sinks", "main", "falcon"]

scalars = st.one_of(
    st.none(), st.booleans(), st.integers(-2**70, 2**70), st.floats(allow_nan=True),
    st.text(max_size=12), st.sampled_from(["1ms", "15Hz", "falcon", "mediator", "main", "1 parsec", "latest"]),
)
keys = st.one_of(st.sampled_from(FIELDS), st.text(max_size=8), st.integers(0, 3))
trees = st.recursive(
    scalars,
    lambda children: st.one_of(st.lists(children, max_size=4), st.dictionaries(keys, children, max_size=5)),
    max_leaves=25,
)


def dump(tree) -> str:
    out = io.StringIO()
    YAML(typ="safe").dump(tree, out)
    return out.getvalue()


def check(report: Report) -> None:
    assert isinstance(report, Report)
    for d in report.diagnostics:
        assert d.message and d.rule
        assert d.line >= 0 and d.column >= 0


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.text(max_size=300))
def test_arbitrary_text(text):
    check(validate_text(text).report)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(trees)
def test_arbitrary_structures(tree):
    check(validate_text(dump({"version": 1, "data": tree}) if not isinstance(tree, dict) else dump(tree)).report)


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_mutated_hallway(hallway_text_cached, data):
    lines = hallway_text_cached.splitlines(keepends=True)
    for _ in range(data.draw(st.integers(1, 4))):
        i = data.draw(st.integers(0, len(lines) - 1))
        action = data.draw(st.sampled_from(["drop", "duplicate", "dedent", "garble"]))
        if action == "drop":
            del lines[i]
        elif action == "duplicate":
            lines.insert(i, lines[i])
        elif action == "dedent":
            lines[i] = lines[i].lstrip(" ")
        else:
            lines[i] = lines[i].replace(":", data.draw(st.sampled_from([" ", "::", ": [", ": 99"])), 1)
    # A small state limit keeps each example fast; reachability is tested on its own.
    check(validate_text("".join(lines), "hallway.yaml", state_limit=300).report)
