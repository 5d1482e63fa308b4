"""The bench's report: one Markdown file with every table, and a PNG of the latency histograms."""

from __future__ import annotations

import math
from pathlib import Path

from hapticop.benchmark.runner import BenchRun, Condition
from hapticop.benchmark.stats import Distribution, Goal, missed_percent, thread_goals

PROBES = ("probe_above", "probe_below")


def _f(value, digits: int = 0) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    return f"{value:.{digits}f}"


def thread_distribution(thread: dict) -> Distribution:
    return Distribution.from_sparse(thread.get("histogram_us", {}), thread["wakeup_latency_us"]["max"])


def realtime_threads(timing: dict) -> list[str]:
    """The composition's own 1 kHz threads, the ones the goals are about (probes excluded)."""
    return [name for name, t in timing["threads"].items() if t["period"] == "1ms" and name not in PROBES]


def goals(condition: Condition) -> list[Goal]:
    baseline = condition.baseline.summary() if condition.baseline else None
    found: list[Goal] = []
    for name in realtime_threads(condition.timing):
        t = condition.timing["threads"][name]
        found += thread_goals(f"{condition.name} {name}", t["wakeup_latency_us"],
                              missed_percent(t["cycles"], t["missed_deadlines"]), baseline)
    for path, limit in (("handle_to_wheel_command", 2000.0), ("lidar_telegram_to_force", 2000.0)):
        e2e = condition.timing.get("latencies", {}).get(path)
        if e2e:
            found.append(Goal(f"{condition.name} {path} p99 (us)", e2e["latency_us"]["p99"] or math.nan, limit))
    loops = sum(t.get("cpu_percent") or 0.0 for name, t in condition.timing["threads"].items() if name not in PROBES)
    simulated = (condition.timing.get("cpu") or {}).get("simulators_percent")
    if simulated is None:
        found.append(Goal(f"{condition.name} CPU of the composition's loops, % of one core (simulators included)",
                          loops, 50.0))
    else:
        found.append(Goal(f"{condition.name} CPU of the composition without its simulated devices, % of one core",
                          loops - simulated, 50.0))
    return found


def markdown(bench: BenchRun) -> str:
    m = bench.machine
    lines = [f"# hapticop bench: {bench.file}", "",
             f"{m['host']}, Linux {m['kernel']}, {m['cpus']} CPUs, Python {m['python']}, {m['date']}; "
             f"{bench.seconds:g} s per condition; wake-up latency and end-to-end latency in us.", ""]
    lines += [f"- {note}" for note in bench.notes] + ([""] if bench.notes else [])
    for c in bench.conditions:
        lines += [f"## {c.name}", "",
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
        for g in all_goals:
            verdict = "yes" if g.met else ("no value" if math.isnan(g.value) else f"no ({g.by:.2f}x the limit)")
            lines.append(f"| {g.what} | {_f(g.value, 2 if g.limit < 1 else 0)} "
                         f"| {_f(g.limit, 2 if g.limit < 1 else 0)} | {verdict} |")
        lines.append("")
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
