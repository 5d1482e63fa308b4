"""Live patches: from a YAML patch to a validated description and a plan of changes."""

from __future__ import annotations

import copy
from pathlib import Path

import pytest

from hapticop.composition import documents
from hapticop.composition.yamlsource import read_file
from hapticop.validation import validate_source
from hapticop.validation.patches import (
    ChangePlan,
    PatchError,
    apply_patch,
    load_patch,
    plan_changes,
    prepare,
    validate_patched,
)

HALLWAY = Path(__file__).resolve().parent.parent / "systems" / "hallway.yaml"


@pytest.fixture(scope="module")
def hallway():
    source = read_file(HALLWAY)
    validated = validate_source(source)
    assert validated.report.ok
    return source.tree, validated.composition


def _refused(tree, text: str) -> PatchError:
    before = copy.deepcopy(tree)
    with pytest.raises(PatchError) as caught:
        prepare(tree, load_patch(text, "p.yaml"), patch_file="p.yaml")
    assert tree == before, "a refused patch must leave the running description unchanged"
    return caught.value


# --- load_patch ---------------------------------------------------------------------


def test_load_json_patch_and_merge_patch():
    ops = load_patch("- {op: replace, path: /activities/haptic/params/driving/k1_per_s, value: 30.0}\n", "p.yaml")
    assert isinstance(ops, list) and ops[0]["op"] == "replace"
    merge = load_patch("activities:\n  haptic:\n    params: {driving: {k1_per_s: 30.0}}\n", "p.yaml")
    assert isinstance(merge, dict) and merge["activities"]["haptic"]["params"]["driving"]["k1_per_s"] == 30.0


@pytest.mark.parametrize(
    "text, rule, line",
    [
        ("activities:\n  haptic: [1,\n", "yaml-syntax", 3),
        ("activities: {}\nactivities: {}\n", "duplicate-key", 2),
        ("- {op: replace, path: /a, value: 1}\n- {op: replace, path: /a, path: /b, value: 1}\n", "duplicate-key", 2),
        ("42\n", "patch-syntax", 1),
        ("just text\n", "patch-syntax", 1),
        ("", "patch-syntax", 1),
        ("- {op: replace, path: /a, value: 1}\n- {op: frobnicate, path: /a}\n", "patch-syntax", 2),
        ("- {op: replace, value: 1}\n", "patch-syntax", 1),
        ("- {op: replace, path: /a}\n", "patch-syntax", 1),
        ("- {op: move, path: /a}\n", "patch-syntax", 1),
        ("- {op: remove, path: no-slash}\n", "patch-syntax", 1),
        ("- just a string\n", "patch-syntax", 1),
        ("op: replace\npath: /activities/haptic/params/driving/k1_per_s\nvalue: 1\n", "patch-syntax", 1),
    ],
)
def test_load_patch_errors_are_located(text, rule, line):
    with pytest.raises(PatchError) as caught:
        load_patch(text, "p.yaml")
    first = caught.value.diagnostics[0]
    assert (first.rule, first.file, first.line) == (rule, "p.yaml", line)
    assert first.column >= 1
    assert first.message


def test_load_patch_raises_only_patch_error():
    for junk in ("\t- x", "a: *nowhere\n", "!!binary x\n", "a: &x [*x]\n", "\x00", "? [a, b]\n: 1\n"):
        try:
            load_patch(junk, "p.yaml")
        except PatchError:
            pass


# --- JSON Patch ---------------------------------------------------------------------------


def test_json_patch_replaces_a_parameter(hallway):
    tree, _ = hallway
    patch = load_patch("- {op: replace, path: /activities/haptic/params/driving/k1_per_s, value: 30.0}\n", "p.yaml")
    new_tree, composition, plan, diff = prepare(tree, patch)
    assert composition.activities["haptic"].params["driving"]["k1_per_s"] == 30.0
    assert plan.params["haptic"]["driving"]["k1_per_s"] == 30.0
    assert plan.params["haptic"]["driving"]["k2_rad_per_s_m"] == 10.0  # the whole new parameter set
    assert plan.params["haptic"]["centring"]["kp_n_per_m"] == 55.0
    assert type(plan.params["haptic"]["driving"]["k1_per_s"]) is float  # plain values, not ruamel's
    assert "activity 'haptic': parameters driving.k1_per_s 28.0 -> 30.0" in plan.describe()
    assert not plan.schedules and not plan.unsupported and not plan.empty
    assert tree["activities"]["haptic"]["params"]["driving"]["k1_per_s"] == 28.0
    assert "-      driving: {k1_per_s: 28.0, " in diff and "+      driving: {k1_per_s: 30.0, " in diff


def test_json_patch_reaches_integer_schedule_ids(hallway):
    tree, _ = hallway
    patch = load_patch("- {op: replace, path: /threads/fieldbus/schedules/1, value: []}\n", "p.yaml")
    new_tree, _, plan, _ = prepare(tree, patch)
    assert plan.schedules == {"fieldbus": {0: [], 1: []}}
    assert list(new_tree["threads"]["fieldbus"]["schedules"]) == [0, 1]  # still integer keys
    assert "thread 'fieldbus': schedule 1 [ethercat, ropod] -> []" in plan.describe()


def test_failing_test_op_refuses_the_patch(hallway):
    tree, _ = hallway
    error = _refused(
        tree,
        "- {op: replace, path: /activities/haptic/params/driving/k2_rad_per_s_m, value: 11.0}\n"
        "- {op: test, path: /activities/haptic/params/driving/k1_per_s, value: 31.0}\n"
        "- {op: replace, path: /activities/haptic/params/driving/k1_per_s, value: 32.0}\n",
    )
    (diagnostic,) = error.diagnostics
    assert diagnostic.rule == "patch-apply"
    assert "operation 1" in diagnostic.message and "/activities/haptic/params/driving/k1_per_s" in diagnostic.message
    assert "28.0" in diagnostic.message
    assert (diagnostic.file, diagnostic.line) == ("p.yaml", 2)


@pytest.mark.parametrize(
    "text",
    [
        "- {op: replace, path: /activities/nothing/params/driving/k1_per_s, value: 1}\n",
        "- {op: remove, path: /activities/haptic/params/no_such_param}\n",
        "- {op: add, path: /threads/main/schedules/1/9, value: haptic}\n",
        "- {op: move, from: /streams/nothing, path: /streams/other}\n",
    ],
)
def test_bad_path_refuses_the_patch(hallway, text):
    tree, _ = hallway
    error = _refused(tree, text)
    (diagnostic,) = error.diagnostics
    assert diagnostic.rule == "patch-apply"
    assert "operation 0" in diagnostic.message
    assert diagnostic.line == 1


def test_replacing_the_whole_document_with_a_list_is_refused(hallway):
    tree, _ = hallway
    assert _refused(tree, "- {op: replace, path: '', value: [1]}\n").diagnostics[0].rule == "patch-apply"


# --- merge patch --------------------------------------------------------------------------


def test_merge_patch_changes_a_schedule(hallway):
    tree, _ = hallway
    patch = load_patch("threads:\n  fieldbus:\n    schedules:\n      1: [ethercat]\n"
                       "      2: [ethercat, ropod]\n", "p.yaml")
    _, _, plan, _ = prepare(tree, patch)
    assert plan.schedules == {
        "fieldbus": {0: [], 1: ["ethercat"], 2: ["ethercat", "ropod"]}}
    lines = plan.describe()
    assert "thread 'fieldbus': schedule 1 [ethercat, ropod] -> [ethercat]" in lines
    assert "thread 'fieldbus': schedule 2 (none) -> [ethercat, ropod]" in lines
    assert not plan.params and not plan.unsupported


def test_merge_patch_null_deletes_and_keeps_the_rest(hallway):
    tree, _ = hallway
    patch = "activities:\n  haptic:\n    params:\n      driving: {k1_per_s: 30.0, k2_rad_per_s_m: null}\n"
    new_tree = apply_patch(tree, load_patch(patch, "p.yaml"))
    params = new_tree["activities"]["haptic"]["params"]
    driving = params["driving"]
    assert driving["k1_per_s"] == 30.0 and "k2_rad_per_s_m" not in driving and driving["dead_zone_m"] == 0.005
    assert params["centring"]["kp_n_per_m"] == 55.0
    assert "k2_rad_per_s_m" in tree["activities"]["haptic"]["params"]["driving"]


def test_json_keys_as_text_reach_integer_schedule_ids(hallway):
    tree, _ = hallway
    new_tree = apply_patch(tree, {"threads": {"fieldbus": {"schedules": {"1": ["ethercat"]}}}})
    assert dict(new_tree["threads"]["fieldbus"]["schedules"]) == {0: [], 1: ["ethercat"]}


# --- invalid results ----------------------------------------------------------------------


def test_patch_making_a_parameter_invalid_is_refused_with_the_validators_diagnostic(hallway):
    tree, _ = hallway
    error = _refused(tree, "- {op: replace, path: /activities/haptic/params/driving/k1_per_s, value: fast}\n")
    assert [d.rule for d in error.diagnostics] == ["bad-value"]
    diagnostic = error.diagnostics[0]
    assert diagnostic.path == ("activities", "haptic", "params", "driving", "k1_per_s")
    assert "fast" in diagnostic.message
    assert diagnostic.line > 0


def test_schedule_naming_an_unknown_activity_is_refused(hallway):
    tree, _ = hallway
    error = _refused(tree, "threads: {fieldbus: {schedules: {1: [ethercat, nobody]}}}\n")
    (diagnostic,) = error.diagnostics
    assert diagnostic.rule == "unknown-activity"
    assert "nobody" in diagnostic.message
    assert diagnostic.path[:4] == ("threads", "fieldbus", "schedules", 1)


def test_validate_patched_returns_the_validated_composition(hallway):
    tree, _ = hallway
    patch = {"activities": {"haptic": {"params": {"driving": {"k2_rad_per_s_m": 12.0}}}}}
    validated = validate_patched(apply_patch(tree, patch))
    assert validated.composition.activities["haptic"].params["driving"]["k2_rad_per_s_m"] == 12.0


# --- unsupported changes ------------------------------------------------------------------


@pytest.mark.parametrize(
    "text, path",
    [
        ("threads: {lidar: {period: 20Hz}}", ("threads", "lidar", "period")),
        ("threads: {fieldbus: {priority: 38}}", ("threads", "fieldbus", "priority")),
        ("- {op: add, path: /threads/lidar/cpus, value: [1]}", ("threads", "lidar", "cpus")),
        # one cleaning stage instead of two: the written-out mediator net changes, its flag map does not
        ("coordination: {standard: {clean: {haptic: null, devices: [haptic, falcon, lidar, ethercat, ropod, "
         "ethercat_watchdog]}}}", ("coordination", "nets", "mediator")),
        ("streams: {scan_ranges: {policy: {kind: queue}}}", ("streams", "scan_ranges", "policy")),
    ],
)
def test_unsupported_change_is_refused_naming_the_path(hallway, text, path):
    tree, _ = hallway
    error = _refused(tree, text + "\n")
    (diagnostic,) = error.diagnostics
    assert diagnostic.rule == "patch-unsupported"
    assert diagnostic.path == path
    assert "restart the system to change it" in diagnostic.message
    assert diagnostic.line > 0


def test_plan_lists_unsupported_changes_without_refusing(hallway):
    tree, old = hallway
    new = validate_patched(apply_patch(tree, {"threads": {"lidar": {"period": "20Hz"}}})).composition
    plan = plan_changes(old, new)
    assert plan.unsupported and plan.unsupported[0][0] == ("threads", "lidar", "period")
    assert any(line.startswith("threads.lidar.period: ") and line.endswith("restart the system to change it")
               for line in plan.describe())


def test_doc_changes_are_not_changes(hallway):
    tree, old = hallway
    new_tree = apply_patch(tree, {"threads": {"lidar": {"doc": "x"}},
                                  "coordination": {"standard": {"doc": "y"}}})
    assert plan_changes(old, validate_patched(new_tree).composition).empty
    assert ChangePlan().empty


# --- diff ---------------------------------------------------------------------------------


def test_diff_shows_the_changed_line_and_keeps_comments(hallway):
    tree, _ = hallway
    new_tree = apply_patch(tree, load_patch("threads:\n  fieldbus:\n    schedules:\n      1: []\n", "p.yaml"))
    diff = documents.diff(tree, new_tree, "hallway.yaml")
    assert diff.startswith("--- a/hallway.yaml\n+++ b/hallway.yaml\n")
    comment = "# the simulated wheels answered the master's last frame meanwhile\n"
    assert "-      1: [ethercat, ropod]    " + comment + "+      1: []" + " " * 19 + comment in diff
    assert "  watchdog:                   # thread 3: watches the EtherCAT slaves, above thread 2\n" in diff
    assert sum(line.startswith(("+", "-")) for line in diff.splitlines()) == 4  # two headers, one change
    assert "+# yaml-language-server: $schema=" in documents.diff({}, new_tree)
    assert documents.diff(tree, copy.deepcopy(tree)) == ""


# --- adding ---------------------------------------------------------------------------------


def test_adding_an_activity_and_its_streams(hallway):
    tree, _ = hallway
    patch = load_patch(
        """\
- op: add
  path: /activities/spare_watchdog
  value: {block: ethercat_watchdog, params: {slaves: 7, expected_working_counter: 12}}
- op: add
  path: /threads/watchdog/schedules/1/-
  value: spare_watchdog
- op: add
  path: /streams/spare_states
  value: {from: ethercat.slave_states, to: [spare_watchdog.slave_states]}
- op: add
  path: /streams/spare_counter
  value: {from: ethercat.working_counter, to: spare_watchdog.working_counter}
""",
        "p.yaml",
    )
    try:
        _, composition, plan, diff = prepare(tree, patch, patch_file="p.yaml")
    except PatchError as error:  # pragma: no cover - shows the validator's findings
        pytest.fail(error.to_text())
    assert plan.added_activities == ["spare_watchdog"]
    assert plan.added_streams == ["spare_states", "spare_counter"]
    assert not plan.removed_activities and not plan.removed_streams and not plan.changed_streams
    assert not plan.unsupported and not plan.params
    assert plan.schedules == {"watchdog": {0: [], 1: ["ethercat_watchdog", "spare_watchdog"]}}
    lines = plan.describe()
    assert "activity 'spare_watchdog' added (block ethercat_watchdog)" in lines
    assert "stream 'spare_counter' added (ethercat.working_counter -> spare_watchdog.working_counter)" in lines
    assert composition.streams["spare_counter"].readers == ["spare_watchdog.working_counter"]
    assert "+  spare_watchdog: {block: ethercat_watchdog" in diff
    assert "spare_watchdog" not in tree["activities"]


def test_removing_an_activity_the_coordination_names_is_refused(hallway):
    tree, _ = hallway
    error = _refused(
        tree,
        "- {op: remove, path: /activities/ethercat_watchdog}\n"
        "- {op: replace, path: /threads/watchdog/schedules/1, value: []}\n"
        "- {op: remove, path: /streams/slave_states}\n"
        "- {op: remove, path: /streams/working_counter}\n",
    )
    assert {d.rule for d in error.diagnostics} == {"unknown-flag"}
    assert all(d.path[:3] == ("coordination", "flag_maps", "mediator") for d in error.diagnostics)


def test_patching_a_patched_description_removes_what_was_added(hallway):
    tree, _ = hallway
    added = {
        "activities": {"spare_watchdog": {"block": "ethercat_watchdog",
                                          "params": {"slaves": 7, "expected_working_counter": 12}}},
        "threads": {"watchdog": {"schedules": {1: ["ethercat_watchdog", "spare_watchdog"]}}},
        "streams": {"spare_states": {"from": "ethercat.slave_states", "to": ["spare_watchdog.slave_states"]},
                    "spare_counter": {"from": "ethercat.working_counter", "to": ["spare_watchdog.working_counter"]}},
    }
    patched_tree, patched, _, _ = prepare(tree, added)
    removal = {
        "activities": {"spare_watchdog": None},
        "threads": {"watchdog": {"schedules": {1: ["ethercat_watchdog"]}}},
        "streams": {"spare_states": None, "spare_counter": None},
    }
    back_tree, _, plan, diff = prepare(patched_tree, removal, old=patched)
    assert plan.removed_activities == ["spare_watchdog"]
    assert plan.removed_streams == ["spare_states", "spare_counter"]
    assert plan.schedules == {"watchdog": {0: [], 1: ["ethercat_watchdog"]}}
    assert documents.diff(tree, back_tree) == ""


def test_changing_max_age_is_a_live_stream_change(hallway):
    tree, old = hallway
    new_tree = apply_patch(tree, {"streams": {"rendered_scan": {"max_age": "300ms"}}})
    plan = plan_changes(old, validate_patched(new_tree).composition)
    assert plan.changed_streams == ["rendered_scan"] and not plan.unsupported
    assert "stream 'rendered_scan': max_age 200ms -> 300ms" in plan.describe()


def test_what_a_run_records_cannot_change_live(hallway):
    tree, old = hallway
    new_tree = apply_patch(tree, {"record": {"streams": ["handle_force"]}})
    plan = plan_changes(old, validate_patched(new_tree).composition)
    assert [path for path, _ in plan.unsupported] == [("record",)]
