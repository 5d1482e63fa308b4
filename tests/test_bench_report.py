"""The bench's statistics and report, on timing recorded from real runs (no timing is asserted)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from hapticop.benchmark import cyclictest, report
from hapticop.benchmark.runner import BenchRun, Condition
from hapticop.benchmark.stats import Distribution, Goal, missed_percent, thread_goals
from hapticop.runtime.report import sparse
from hapticop.runtime.tallies import Histograms
from hapticop.runtime.timing import BINS, percentile_us

FIXTURES = Path(__file__).parent / "fixtures" / "bench"


def recorded_timing() -> dict:
    return json.loads((FIXTURES / "timing-bench-idle.json").read_text())


def test_percentiles_are_exact_to_the_bin():
    d = Distribution(np.array([0, 50, 40, 9, 0, 1], dtype=np.int64))  # 100 samples
    assert d.count == 100
    assert d.percentile(50) == 1 and d.percentile(90) == 2 and d.percentile(99) == 3 and d.percentile(99.9) == 5
    assert d.percentile(100) == 5 and d.maximum == 5
    assert math.isnan(Distribution(np.zeros(3, dtype=np.int64)).percentile(50))


def test_sparse_histograms_round_trip_and_agree_with_the_runtime():
    histogram = np.zeros((1, BINS), dtype=np.int64)
    maximum = np.zeros(1, dtype=np.int64)
    rng = np.random.default_rng(1)
    counts = Histograms(histogram, maximum, np.zeros(1, dtype=np.int64))
    for value_ns in rng.gamma(2.0, 20_000.0, size=5000).astype(np.int64):
        counts.count(0, int(value_ns))
    d = Distribution.from_sparse(sparse(histogram[0]), maximum[0] / 1000)
    for q in (50, 99, 99.9):
        assert d.percentile(q) == percentile_us(histogram[0], q)
    assert d.maximum == maximum[0] / 1000


def test_recorded_run_summaries_match_their_histograms():
    for name, thread in recorded_timing()["threads"].items():
        d = report.thread_distribution(thread)
        assert d.count == sum(thread["histogram_us"].values()), name
        for q, key in ((50, "p50"), (99, "p99"), (99.9, "p99.9")):
            assert d.percentile(q) == thread["wakeup_latency_us"][key], (name, key)


def test_missed_deadlines_count_skipped_periods():
    assert missed_percent(9995, 5) == pytest.approx(0.05)
    assert missed_percent(1000, 0) == 0.0
    assert math.isnan(missed_percent(0, 0))


def test_cyclictest_output_is_parsed_across_threads():
    d = cyclictest.parse((FIXTURES / "cyclictest-2s.txt").read_text())
    assert d.count == 4000  # "# Total: 000002000 000002000": two CPUs, 2 s at 1 kHz
    assert d.maximum == 257  # the larger of the two threads' maxima
    assert 17 <= d.percentile(50) <= d.percentile(99) <= d.percentile(99.9) <= 257


def test_cyclictest_overflows_land_in_the_last_bin():
    text = "000010 000003\t000001\n# Max Latencies: 00010 25000\n# Histogram Overflows: 00000 00002\n"
    d = cyclictest.parse(text)
    assert d.count == 6 and d.counts[-1] == 2 and d.maximum == 25000


def test_goals_compare_with_the_machine_and_say_by_how_much():
    goals = thread_goals("main", {"p99": 90.0, "p99.9": 500.0}, 0.15, {"p99": 50.0, "p99.9": 200.0})
    by_name = {g.what: g for g in goals}
    assert by_name["main: wake-up p99 (us)"].limit == 75.0 and not by_name["main: wake-up p99 (us)"].met
    assert by_name["main: wake-up p99 (us)"].ratio == pytest.approx(1.8)  # 1.8x cyclictest's
    assert by_name["main: wake-up p99.9 (us)"].by == pytest.approx(1.25)
    assert not by_name["main: missed deadlines %"].met and by_name["main: missed deadlines %"].ratio is None
    assert Goal("x", 0.04, 0.05).met and not Goal("x", math.nan, 1.0).met
    assert Goal("speed", 25.0, 20.0, at_least=True).met and not Goal("speed", 15.0, 20.0, at_least=True).met
    assert [g.what for g in thread_goals("t", {"p99": 1, "p99.9": 1}, 0.0, None)] == ["t: missed deadlines %"]


def test_missed_deadlines_are_judged_against_the_empty_probe_loop():
    probe = "t: missed deadlines % against the empty probe loop's"
    loop = {g.what: g for g in thread_goals("t", {}, 0.03, None, probe_missed_pct=0.02, probe_periods=10_000)}
    assert loop[probe].limit == pytest.approx(0.04) and loop[probe].met and loop[probe].ratio == pytest.approx(1.5)
    # a probe that missed nothing is a limit of one missed period, not of zero
    quiet = {g.what: g for g in thread_goals("t", {}, 0.03, None, probe_missed_pct=0.0, probe_periods=10_000)}
    assert quiet[probe].machine == pytest.approx(0.01) and not quiet[probe].met


def test_report_has_every_table_and_a_histogram(tmp_path):
    timing = recorded_timing()
    baseline = cyclictest.parse((FIXTURES / "cyclictest-2s.txt").read_text())
    bench = BenchRun("systems/bench.yaml", 10.0, {"host": "h", "kernel": "k", "cpus": 2, "python": "3.11",
                                                    "date": "d", "root": True},
                     [Condition("idle", timing, baseline, 0, tmp_path)])
    text = report.markdown(bench)
    assert "| cyclictest (the machine's limit) | 80 | | 4000 |" in text
    for thread in timing["threads"]:
        assert f"| {thread} |" in text
    for path in timing["latencies"]:
        assert f"| {path} |" in text
    assert "probe below minus probe above" in text
    main = timing["threads"]["main"]
    assert f"| idle main: wake-up p99 (us) | {main['wakeup_latency_us']['p99']:.0f} |" in text
    assert "## goals" in text
    assert "## goals over 1 round" in text and "Verdict" in text
    picture = report.histogram_png(bench, tmp_path / "latency.png")
    assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _rounds(tmp_path, cyclictest_p99s: list[int], probe_missed: int = 0) -> BenchRun:
    """Idle rounds of the recorded run, cyclictest beside each with its p99 near the given value."""
    conditions = []
    for round_, p99 in enumerate(cyclictest_p99s, start=1):
        timing = recorded_timing()
        timing["threads"]["probe_above"]["missed_deadlines"] = probe_missed
        counts = np.zeros(p99 + 2, dtype=np.int64)
        counts[10], counts[p99] = 980, 20
        conditions.append(Condition("idle", timing, Distribution(counts), 0, tmp_path, round_))
    return BenchRun("systems/bench.yaml", 10.0, {"host": "h", "kernel": "k", "cpus": 2, "python": "3.11",
                                                 "date": "d", "root": True}, conditions, repeat=len(cyclictest_p99s))


def test_repeated_rounds_give_each_figure_s_spread_and_a_verdict(tmp_path):
    bench = _rounds(tmp_path, [60, 70, 80])
    text = report.markdown(bench)
    assert "## goals over 3 rounds" in text
    row = next(line for line in text.splitlines() if line.startswith("| idle main: wake-up p99 (us) |"))
    cells = [c.strip() for c in row.split("|")[1:-1]]
    assert cells[1] == cells[2] == cells[3]  # the same recorded run three times: no spread in the figure
    assert cells[4].count("/") == 2  # ... but a spread in its ratio to each round's own cyclictest
    assert "Verdict:" in text and "goals met" in text
    assert not report.noise(bench)


def test_a_machine_too_noisy_for_a_verdict_is_named_so(tmp_path):
    spread = report.noise(_rounds(tmp_path, [50, 150]))
    assert spread and "ranges 50-150 us between rounds" in spread[0]
    missing = report.noise(_rounds(tmp_path, [60], probe_missed=100))
    assert missing and "the empty probe loop itself misses" in missing[0]
    text = report.markdown(_rounds(tmp_path, [60], probe_missed=100))
    assert "Verdict: none. The machine itself is too noisy" in text
    starved = _rounds(tmp_path, [60])
    simulators = dict(starved.conditions[0].timing["threads"]["main"], simulation=True, cycles=100,
                      missed_deadlines=900)
    starved.conditions[0].timing["threads"]["simulators"] = simulators
    assert any("the simulators' thread 'simulators' missed 90 %" in reason for reason in report.noise(starved))


def test_the_loops_goals_leave_out_probes_and_threads_of_simulators():
    timing = recorded_timing()
    timing["threads"]["simulators"] = dict(timing["threads"]["main"], simulation=True, deploy="process")
    assert "simulators" not in report.realtime_threads(timing)
    assert "main" in report.realtime_threads(timing) and "probe_above" not in report.realtime_threads(timing)


def test_the_framework_s_work_is_measured_per_loop_of_the_system():
    """Which loops are measured, and that a cycle's framework share is part of it (no speed judged)."""
    from hapticop.benchmark.overhead import measure

    found = measure(Path(__file__).parents[1] / "systems" / "hallway.yaml", cycles=20, warm=200)
    assert set(found) == {"main", "fieldbus", "watchdog"}  # not the simulators' thread, nor the 15 Hz ones
    assert found["main"]["activities"] == 3
    for figures in found.values():
        assert 0 <= figures["framework_p50"] <= figures["cycle_p50"]
