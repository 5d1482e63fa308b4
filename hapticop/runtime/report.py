"""The table a run ends with: how well every thread kept time, what every activity cost."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hapticop.composition.units import format_period
from hapticop.runtime.region import Region
from hapticop.runtime.timing import BINS, Summary

CEILING_US = BINS - 1  # the histogram's last bin: a percentile there is only known to be at least this


@dataclass(frozen=True)
class Ending:
    """The counters as the run started ending (its duration reached, a stop asked): the window the
    figures describe ends here. What the loops count after it (cleaning, processes leaving) is the
    shutdown's, reported beside the run's rather than in it, as the start-up's first cycles are left out."""

    at_ns: int
    cycles: np.ndarray
    missed: np.ndarray
    cpu_ns: np.ndarray

    @classmethod
    def of(cls, region: Region, now_ns: int) -> Ending:
        """Tell every loop the run is ending (their histograms stop counting), then note the counters."""
        region.system[Region.ENDING] = 1
        return cls(now_ns, region.cycles.copy(), region.missed.copy(), region.cpu_ns.copy())


def timing(region: Region, composition, elapsed_ns: int | None = None, ending: Ending | None = None) -> dict:
    """Every figure of a run, from the region's counters. `elapsed_ns` (wall time the loops ran)
    turns each thread's CPU time into a share of one core; histograms are kept, sparse, so a
    report can be drawn from the file alone. With an `ending`, cycles, misses and CPU time are
    those before it, and each thread's misses after it are `missed_while_ending`."""
    layout = region.layout
    counted = ending or Ending(0, region.cycles, region.missed, region.cpu_ns)
    simulating = _simulation_threads(region, composition)
    threads = {}
    for name, index in layout.thread_index.items():
        # A copy: the running loops go on counting, and a histogram read while it changes
        # makes numpy's nonzero fail (`status` on the control socket reads a live system).
        histogram = region.latency[index].copy()
        summary = Summary.of(histogram, int(region.latency_max[index]))
        cycles = int(counted.cycles[index] - region.cycles_base[index])
        missed = int(counted.missed[index])
        cpu_ns = int(counted.cpu_ns[index] - region.cpu_base[index])
        threads[name] = {
            "period": format_period(composition.threads[name].period),
            "priority": composition.threads[name].priority,
            "deploy": composition.threads[name].deploy,
            "simulation": name in simulating,
            "cycles": cycles,
            "missed_deadlines": missed,
            "missed_percent": round(100.0 * missed / (cycles + missed), 3) if cycles + missed else None,
            "missed_while_ending": int(region.missed[index]) - missed,
            "cpu_percent": round(100.0 * cpu_ns / elapsed_ns, 1) if elapsed_ns and cpu_ns else None,
            "wakeup_latency_us": _numbers(summary),
            "cycle_us": _numbers(Summary.of(region.busy[index].copy(), int(region.busy_max[index]))),
            "histogram_us": sparse(histogram),
        }
    activities = {}
    for name, index in layout.activity_index.items():
        summary = Summary.of(region.compute[index].copy(), int(region.compute_max[index]))
        activities[name] = {"steps": summary.count, "compute_us": _numbers(summary)}
        if region.sim_ns[index]:
            activities[name]["simulation_us_per_step"] = round(
                int(region.sim_ns[index]) / 1000 / max(1, summary.count), 1)
    if elapsed_ns:  # the system's own CPU: the loops' CPU less the simulators' (whole threads, or their blocks' share)
        inside = {a for t in simulating for members in composition.threads[t].schedules.values() for a in members}
        simulated = 100.0 * sum(int(region.sim_ns[i]) for a, i in layout.activity_index.items() if a not in inside)
        simulated = simulated / elapsed_ns + sum(threads[t]["cpu_percent"] or 0.0 for t in simulating)
        loops = sum(t["cpu_percent"] or 0.0 for t in threads.values())
        cpu = {"loops_percent": round(loops, 1), "simulators_percent": round(simulated, 1),
               "without_simulators_percent": round(loops - simulated, 1)}
    else:
        cpu = None
    latencies = {}
    for slot, (name, spec) in enumerate(composition.latencies.items()):
        summary = Summary.of(region.e2e[slot], int(region.e2e_max[slot]))
        latencies[name] = {"from": spec.source, "to": spec.sink, "samples": summary.count,
                           "latency_us": _numbers(summary), "histogram_us": sparse(region.e2e[slot])}
    return {"started_ns": int(region.system[Region.STARTED_NS]),
            "elapsed_s": round(elapsed_ns / 1e9, 3) if elapsed_ns else None, "cpu": cpu, "threads": threads,
            "activities": activities, "latencies": latencies}


def _simulation_threads(region: Region, composition) -> set[str]:
    """Threads that run simulators only (each counted its simulation time): no real system has them."""
    index = region.layout.activity_index
    found = set()
    for name, spec in composition.threads.items():
        members = {a for schedule in spec.schedules.values() for a in schedule if a in index}
        if members and all(region.sim_ns[index[a]] for a in members):
            found.add(name)
    return found


def sparse(histogram) -> dict[str, int]:
    """A 1 us histogram as {bin: count} for its non-empty bins (JSON keys are strings)."""
    return {str(int(b)): int(histogram[b]) for b in histogram.nonzero()[0]}


def _numbers(summary: Summary) -> dict:
    clean = lambda v: None if math.isnan(v) else round(v, 1)  # noqa: E731
    return {"p50": clean(summary.p50_us), "p99": clean(summary.p99_us), "p99.9": clean(summary.p999_us),
            "max": clean(summary.max_us)}


def write_timing(data: dict, run_dir: Path) -> Path:
    path = run_dir / "timing.json"
    path.write_text(json.dumps(data, indent=2))
    return path
