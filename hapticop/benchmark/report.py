"""The bench's report: one Markdown file with every table, and a PNG of the latency histograms.

Every goal is judged per run against that run's own limits (cyclictest beside it, the empty
probe loop inside it); over repeated rounds the report gives each figure's spread and judges
the median. When the machine's own limits are themselves out of bounds, it says so instead
of a verdict: the figures then describe the machine more than the system.
"""

from __future__ import annotations

import math
import statistics
from pathlib import Path

from hapticop.benchmark.runner import BenchRun, Condition
from hapticop.benchmark.stats import MISSED_LIMIT_PERCENT, Distribution, Goal, missed_percent, thread_goals

PROBES = ("probe_above", "probe_below")
EMPTY_PROBE = "probe_above"  # the empty loop in its own process, above the application: the machine's misses
MAIN_CYCLE_US = 150.0  # the main loop's compute p99 goal (issue 32): room for a late wake-up in 1 ms
FRAMEWORK_US = 30.0
CPU_PERCENT = 40.0  # the system without its simulated devices, of one core of two
VIRTUAL_SPEED = 10.0  # the full hallway under the virtual clock, simulated s per CPU s (desk applications: 20)
NOISY_CYCLICTEST_P999_US = 500.0  # docs/realtime.md §3: beyond this the machine itself misses the wake-up goals
NOISY_SPREAD = 2.0  # cyclictest's p99 differing more than this between rounds of one condition
STARVED_SIMULATORS_PERCENT = 10.0  # simulators missing more of their periods leave the loops without their load


def _f(value, digits: int = 0) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    return f"{value:.{digits}f}"


def _n(value: float) -> str:
    """A figure with the digits it needs: shares of a percent keep three."""
    return _f(value, 3 if abs(value) < 1 else 1)


def thread_distribution(thread: dict) -> Distribution:
    return Distribution.from_sparse(thread.get("histogram_us", {}), thread["wakeup_latency_us"]["max"])


def realtime_threads(timing: dict) -> list[str]:
    """The composition's own 1 kHz threads, the ones the goals are about (probes and simulators excluded)."""
    return [name for name, t in timing["threads"].items()
            if t["period"] == "1ms" and name not in PROBES and not t.get("simulation")]


def goals(condition: Condition) -> list[Goal]:
    baseline = condition.baseline.summary() if condition.baseline else None
    probe = condition.timing["threads"].get(EMPTY_PROBE)
    probe_missed = missed_percent(probe["cycles"], probe["missed_deadlines"]) if probe else None
    probe_periods = probe["cycles"] + probe["missed_deadlines"] if probe else 0
    found: list[Goal] = []
    for name in realtime_threads(condition.timing):
        t = condition.timing["threads"][name]
        found += thread_goals(f"{condition.name} {name}", t["wakeup_latency_us"],
                              missed_percent(t["cycles"], t["missed_deadlines"]), baseline, probe_missed,
                              probe_periods)
    for name, t in condition.timing["threads"].items():
        if t.get("deploy") == "main" and t.get("cycle_us"):
            found.append(Goal(f"{condition.name} {name}: compute p99 per cycle (us)",
                              t["cycle_us"]["p99"] or math.nan, MAIN_CYCLE_US))
    for path, limit in (("handle_to_wheel_command", 1500.0), ("lidar_telegram_to_force", 1500.0)):
        e2e = condition.timing.get("latencies", {}).get(path)
        if e2e:
            found.append(Goal(f"{condition.name} {path} p99 (us)", e2e["latency_us"]["p99"] or math.nan, limit))
    loops = sum(t.get("cpu_percent") or 0.0 for name, t in condition.timing["threads"].items() if name not in PROBES)
    simulated = (condition.timing.get("cpu") or {}).get("simulators_percent")
    if simulated is None:
        found.append(Goal(f"{condition.name} CPU of the composition's loops, % of one core (simulators included)",
                          loops, CPU_PERCENT))
    else:
        found.append(Goal(f"{condition.name} CPU of the composition without its simulated devices, % of one core",
                          loops - simulated, CPU_PERCENT))
    return found


def round_goals(bench: BenchRun) -> list[list[Goal]]:
    """Every goal of each round: the conditions' own, the framework's work, the virtual clock's speed."""
    rounds: list[list[Goal]] = []
    for round_ in range(1, bench.repeat + 1):
        found = [g for c in bench.conditions if c.round == round_ for g in goals(c)]
        if len(bench.overhead) >= round_:
            for loop, figures in bench.overhead[round_ - 1].items():
                found.append(Goal(f"framework work per {loop} cycle, p50 (us)", figures["framework_p50"],
                                  FRAMEWORK_US))
        if len(bench.virtual_speed) >= round_:
            speed = bench.virtual_speed[round_ - 1]
            found.append(Goal("virtual clock, simulated s per s of CPU time (at least)", speed, VIRTUAL_SPEED,
                              at_least=True))
        rounds.append(found)
    return rounds


def noise(bench: BenchRun) -> list[str]:
    """Why the machine is too noisy for a verdict (empty: it is not)."""
    reasons = []
    by_condition: dict[str, list[float]] = {}
    for c in bench.conditions:
        if c.baseline:
            s = c.baseline.summary()
            by_condition.setdefault(c.name, []).append(s["p99"])
            if s["p99.9"] > NOISY_CYCLICTEST_P999_US:
                reasons.append(f"round {c.round} {c.name}: cyclictest's own p99.9 is {s['p99.9']:.0f} us "
                               f"(over {NOISY_CYCLICTEST_P999_US:.0f})")
        for name, t in c.timing["threads"].items():
            missed = missed_percent(t["cycles"], t["missed_deadlines"])
            if t.get("simulation") and t["period"] == "1ms" and missed > STARVED_SIMULATORS_PERCENT:
                reasons.append(f"round {c.round} {c.name}: the simulators' thread '{name}' missed {missed:.0f} % of "
                               "its periods, so the loops ran without the devices' load")
        probe = c.timing["threads"].get(EMPTY_PROBE)
        if probe:
            missed = missed_percent(probe["cycles"], probe["missed_deadlines"])
            if missed > MISSED_LIMIT_PERCENT:
                reasons.append(f"round {c.round} {c.name}: the empty probe loop itself misses {missed:.3f} % "
                               f"(over {MISSED_LIMIT_PERCENT} %)")
    for name, p99s in by_condition.items():
        if len(p99s) > 1 and min(p99s) > 0 and max(p99s) / min(p99s) > NOISY_SPREAD:
            reasons.append(f"{name}: cyclictest's p99 ranges {min(p99s):.0f}-{max(p99s):.0f} us between rounds")
    return reasons


def summary(bench: BenchRun) -> list[str]:
    """Each goal over the rounds: min, median and max of the figure (and of its ratio to the machine's
    own), judged on the median; then the verdict, or why there is none."""
    rounds = round_goals(bench)
    if not any(rounds):
        return []
    names = list(dict.fromkeys(g.what for found in rounds for g in found))
    lines = [f"## goals over {bench.repeat} round{'s' if bench.repeat != 1 else ''}", "",
             "| goal | min | median | max | x machine (min/median/max) | limit | median met | all met |",
             "|---|---|---|---|---|---|---|---|"]
    met = total = 0
    for name in names:
        found = [g for r in rounds for g in r if g.what == name]
        values = [g.value for g in found if not math.isnan(g.value)]
        first = found[0]
        if not values:
            lines.append(f"| {name} | - | - | - | - | {_n(first.limit)} | no value | no |")
            total += 1
            continue
        median = statistics.median(values)
        ratios = [g.ratio for g in found if g.ratio is not None and not math.isnan(g.value)]
        ratio = (f"{min(ratios):.2f} / {statistics.median(ratios):.2f} / {max(ratios):.2f}" if ratios else "")
        limit = statistics.median(g.limit for g in found)
        ok = Goal(name, median, limit, at_least=first.at_least).met
        met, total = met + ok, total + 1
        lines.append(f"| {name} | {_n(min(values))} | {_n(median)} | {_n(max(values))} | {ratio} | {_n(limit)} "
                     f"| {'yes' if ok else f'no ({median / limit:.2f}x)' if limit else 'no'} "
                     f"| {'yes' if all(g.met for g in found) else 'no'} |")
    reasons = noise(bench)
    lines.append("")
    if reasons:
        lines.append("**Verdict: none. The machine itself is too noisy for one:** " + "; ".join(reasons) + ". "
                     "The figures above describe this machine at this time; rerun on a quieter one.")
    else:
        lines.append(f"**Verdict: {met} of {total} goals met** (median of {bench.repeat} round"
                     f"{'s' if bench.repeat != 1 else ''}).")
    lines.append("")
    return lines


def markdown(bench: BenchRun) -> str:
    m = bench.machine
    lines = [f"# hapticop bench: {bench.file}", "",
             f"{m['host']}, Linux {m['kernel']}, {m['cpus']} CPUs, Python {m['python']}, {m['date']}; "
             f"{bench.seconds:g} s per condition, {bench.repeat} round{'s' if bench.repeat != 1 else ''}; "
             "wake-up latency and end-to-end latency in us.", ""]
    lines += [f"- {note}" for note in bench.notes] + ([""] if bench.notes else [])
    for round_, (loops, speed) in enumerate(zip(bench.overhead, bench.virtual_speed), start=1):
        lines += [f"## round {round_}: the framework's work per cycle (virtual clock, us)", "",
                  "| loop | activities | cycle p50 | cycle p99 | framework p50 | framework p99 |",
                  "|---|---|---|---|---|---|"]
        lines += [f"| {loop} | {f['activities']} | {f['cycle_p50']:.1f} | {f['cycle_p99']:.1f} | "
                  f"{f['framework_p50']:.1f} | {f['framework_p99']:.1f} |" for loop, f in loops.items()]
        lines += ["", f"Virtual clock: {speed:.1f} simulated s per s of CPU time.", ""]
    for c in bench.conditions:
        lines += [f"## {c.name}" + (f", round {c.round}" if bench.repeat > 1 else ""), "",
                  "| thread | priority | deploy | cycles | p50 | p99 | p99.9 | max | missed | CPU % |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
        if c.baseline:
            s = c.baseline.summary()
            lines.append(f"| cyclictest (the machine's limit) | 80 | | {c.baseline.count} | {_f(s['p50'])} | "
                         f"{_f(s['p99'])} | {_f(s['p99.9'])} | {_f(s['max'])} | | |")
        for name, t in c.timing["threads"].items():
            lat = t["wakeup_latency_us"]
            missed = f"{t['missed_deadlines']} ({_f(missed_percent(t['cycles'], t['missed_deadlines']), 3)} %)"
            lines.append(f"| {name} | {t.get('priority') or '-'} | {t.get('deploy', '')} | {t['cycles']} | "
                         f"{_f(lat['p50'])} | {_f(lat['p99'])} | {_f(lat['p99.9'])} | {_f(lat['max'])} | {missed} | "
                         f"{_f(t.get('cpu_percent'), 1)} |")
        probes = [c.timing["threads"].get(p) for p in PROBES]
        if all(probes) and all(p["cycles"] for p in probes):
            above, below = (p["wakeup_latency_us"] for p in probes)
            lines += ["", "Application latency estimated as in the thesis (table 7.1), probe below minus probe "
                      f"above: max {_f(below['max'] - above['max'])}, p99.9 {_f(below['p99.9'] - above['p99.9'])}, "
                      f"p99 {_f(below['p99'] - above['p99'])}."]
        if c.timing.get("latencies"):
            lines += ["", "| end-to-end | from | to | samples | p50 | p99 | p99.9 | max |",
                      "|---|---|---|---|---|---|---|---|"]
            for name, e in c.timing["latencies"].items():
                lat = e["latency_us"]
                lines.append(f"| {name} | {e['from']} | {e['to']} | {e['samples']} | {_f(lat['p50'])} | "
                             f"{_f(lat['p99'])} | {_f(lat['p99.9'])} | {_f(lat['max'])} |")
        lines += ["", "| activity | steps | compute p50 | p99 | max |", "|---|---|---|---|---|"]
        for name, a in c.timing["activities"].items():
            comp = a["compute_us"]
            lines.append(f"| {name} | {a['steps']} | {_f(comp['p50'])} | {_f(comp['p99'])} | {_f(comp['max'])} |")
        if c.returncode:
            lines += ["", f"The composition exited with status {c.returncode}; see {c.run_dir}."]
        lines.append("")
    all_goals = [g for c in bench.conditions for g in goals(c)]
    if all_goals:
        lines += ["## goals", "", "| goal | value | limit | met |", "|---|---|---|---|"]
        for c in bench.conditions:
            for g in goals(c):
                verdict = "yes" if g.met else ("no value" if math.isnan(g.value) else f"no ({g.by:.2f}x the limit)")
                what = g.what if bench.repeat == 1 else f"round {c.round} {g.what}"
                lines.append(f"| {what} | {_f(g.value, 2 if g.limit < 1 else 0)} "
                             f"| {_f(g.limit, 2 if g.limit < 1 else 0)} | {verdict} |")
        lines.append("")
    lines += summary(bench)
    return "\n".join(lines)


def histogram_png(bench: BenchRun, path: Path) -> Path | None:
    """Wake-up latency histograms per condition, log counts; None when matplotlib is missing."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    conditions = bench.conditions
    figure, axes = plt.subplots(len(conditions), 1, figsize=(9, 3.2 * len(conditions)), squeeze=False)
    for axis, c in zip(axes[:, 0], conditions):
        series = [(f"cyclictest (p99 {_f(c.baseline.percentile(99))} us)", c.baseline)] if c.baseline else []
        for name, t in c.timing["threads"].items():
            if t["period"] == "1ms" and t["cycles"]:
                d = thread_distribution(t)
                series.append((f"{name} (p99 {_f(d.percentile(99))} us)", d))
        top = max((d.percentile(99.9) for _, d in series if d.count), default=100.0)
        limit = int(min(max(top * 1.5, 50), 20_000))
        for label, d in series:
            counts = d.counts[:limit]
            axis.step(range(counts.size), counts, where="post", label=label, linewidth=1)
        axis.set_yscale("log")
        axis.set_xlim(0, limit)
        axis.set_xlabel("wake-up latency (us)")
        axis.set_ylabel("cycles")
        axis.set_title(f"{c.name}")
        axis.legend(fontsize=7)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path
