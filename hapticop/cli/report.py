"""What `hapticop compose` prints: the timing table, the results' tables, the recording's summary, the progress line."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from hapticop.runtime.report import CEILING_US


def plain(value: float, digits: int = 1) -> str:
    """A number for a table: fixed point, never scientific notation (1234567.8, not 1.23457e+06)."""
    text = f"{value:.{digits}f}"
    return text.rstrip("0").rstrip(".") if "." in text else text


def significant(value: float, digits: int = 4) -> str:
    """A number to `digits` significant digits, still in fixed point (0.0001234, 1235000)."""
    if isinstance(value, int) or not math.isfinite(value):
        return str(value)
    return np.format_float_positional(value, precision=digits, unique=False, fractional=False, trim="-")


def _cell(value) -> str:
    return "-" if value is None else plain(value)


def _percentile(value) -> str:
    """A percentile read off the histogram; in its last bin it is a floor, not a figure."""
    return f">= {CEILING_US}" if value is not None and value >= CEILING_US else _cell(value)


def print_timing(data: dict, console: Console, virtual: bool) -> None:
    table = Table(title="threads" + (" (virtual clock: no wake-up latency)" if virtual else ""), title_justify="left")
    for column in ("thread", "period", "cycles", "wake p50 us", "p99", "p99.9", "max", "missed", "CPU %"):
        table.add_column(column, justify="right" if column != "thread" else "left")
    for name, t in data["threads"].items():
        lat = t["wakeup_latency_us"]
        missed = str(t["missed_deadlines"]) + (f" ({plain(t['missed_percent'], 3)} %)" if t.get("missed_percent")
                                               else "")
        table.add_row(name, t["period"], str(t["cycles"]), _percentile(lat["p50"]), _percentile(lat["p99"]),
                      _percentile(lat["p99.9"]), _cell(lat["max"]), missed, _cell(t.get("cpu_percent")))
    console.print(table)
    late = ", ".join(f"{name} {t['missed_while_ending']}" for name, t in data["threads"].items()
                     if t.get("missed_while_ending"))
    if late:
        console.print(f"missed while the run ended (cleaning, processes leaving), not counted above: {late}")
    if data.get("latencies"):
        table = Table(title="end-to-end latencies", title_justify="left")
        for column in ("path", "from", "to", "samples", "p50 us", "p99", "p99.9", "max"):
            table.add_column(column, justify="right" if column in ("samples", "p50 us", "p99", "p99.9", "max")
                             else "left")
        for name, e in data["latencies"].items():
            lat = e["latency_us"]
            table.add_row(name, e["from"], e["to"], str(e["samples"]), _percentile(lat["p50"]),
                          _percentile(lat["p99"]), _percentile(lat["p99.9"]), _cell(lat["max"]))
        console.print(table)
    table = Table(title="activities", title_justify="left")
    for column in ("activity", "steps", "compute p50 us", "p99", "max", "of which simulation us"):
        table.add_column(column, justify="right" if column != "activity" else "left")
    for name, a in data["activities"].items():
        c = a["compute_us"]
        table.add_row(name, str(a["steps"]), _percentile(c["p50"]), _percentile(c["p99"]), _cell(c["max"]),
                      _cell(a.get("simulation_us_per_step")))
    console.print(table)
    if data.get("cpu"):
        cpu = data["cpu"]
        console.print(f"CPU of the loops: {plain(cpu['loops_percent'])} % of one core, of which simulated devices "
                      f"{plain(cpu['simulators_percent'])} %: the system itself "
                      f"{plain(cpu['without_simulators_percent'])} %")
    for line in simulation_lateness(data):
        console.print(line)


def simulation_lateness(data: dict, limit_percent: float = 1.0) -> list[str]:
    """Simulated threads that fell behind real time, said as the simulation's lateness.

    A simulated device that answers late looks to the system like a device that fails; the
    reader must know which it was before blaming the system (or the hardware it stands in for).
    """
    return [f"the simulation fell behind real time: thread {name} missed {plain(t['missed_percent'], 3)} % of its "
            "periods; a late or missing device sample in this run may be the simulation's, not the system's"
            for name, t in data["threads"].items()
            if t.get("simulation") and (t.get("missed_percent") or 0.0) >= limit_percent]


def print_results(run_dir: Path, console: Console) -> None:
    """Tables that activities left as results*.json in the run directory (metrics of a run)."""
    for path in sorted(run_dir.glob("results*.json")):
        data = json.loads(path.read_text())
        table = Table(title=data.get("title", path.stem), title_justify="left")
        for column in ("metric", "value", "target", "ok"):
            table.add_column(column, justify="left" if column == "metric" else "right")
        for row in data["rows"]:
            raw = row["value"]
            if raw is None or isinstance(raw, str):
                value = "-" if raw is None else raw
            else:
                value = f"{significant(raw)} {row['unit']}".strip()
            ok = {True: "[green]yes[/]", False: "[red]no[/]", None: ""}[row["ok"]]
            table.add_row(row["metric"], value, row["target"], ok)
        console.print(table)
        if data.get("picture"):
            console.print(f"picture: {run_dir / data['picture']}")


def closing_line(status: int, name: str, missed: list[str], check: bool) -> tuple[int, str]:
    """The run's exit status and the last line that says it (`compose`).

    A run that ran cleanly but missed its own targets is no plain success: the line says which
    targets were missed; with `--check` the status is 1, without it the run's own 0 stays
    (docs/running.md, exit statuses).
    """
    if status != 0 or not missed:
        return status, f"exit: {name} ({status})"
    targets = f"{len(missed)} target{'s' if len(missed) > 1 else ''} missed ({'; '.join(missed)})"
    if check:
        return 1, f"exit: failure (1): {targets}"
    return 0, f"exit: success (0), but {targets}; --check makes that exit 1"


def missed_targets(run_dir: Path) -> list[str]:
    """The rows of the run's results*.json whose verdict is "no", as "title: metric" (for `compose --check`)."""
    missed = []
    for path in sorted(run_dir.glob("results*.json")):
        data = json.loads(path.read_text())
        missed += [f"{data.get('title', path.stem)}: {row['metric']}" for row in data["rows"] if row["ok"] is False]
    return missed


def print_recording(recording: dict, console: Console) -> None:
    """What the recorder wrote, and every sample it lost (none is the goal)."""
    streams = recording["streams"]
    recorded = sum(s["recorded"] for s in streams.values())
    dropped = {name: s["dropped"] for name, s in streams.items() if s["dropped"]}
    if recording.get("view"):
        view = recording["view"]
        cost = "" if recording["clock"] == "virtual" or not recording.get("elapsed_s") else \
            f"; its process used {100 * recording['cpu_s'] / recording['elapsed_s']:.1f} % of a core"
        console.print(f"live view: {view['address']}, {view['sent']} messages sent{cost}")
    if recording["path"] is None:
        return  # shown only: the newest samples, nothing to lose
    console.print(f"recording: {recording['path']} ({recorded} samples of {len(streams)} streams, "
                  f"{recording['clock']} clock)")
    if dropped:
        lost = ", ".join(f"{name} {n}" for name, n in dropped.items())
        console.print(f"[red]recorder dropped {sum(dropped.values())} samples[/]: {lost}")
    else:
        console.print("recorder dropped no samples")


def progress_line(system, console: Console, every_s: float = 0.5) -> None:
    """One updating status line while a system runs (a daemon thread: never the cycle's business)."""
    import time

    region, layout = system.region, system.layout
    started = int(region.system[region.STARTED_NS])
    while system.built is not None and not system.finished:
        seconds = (system.clock.now_ns() - started) / 1e9
        running = sum(1 for i in layout.owner_index.values() if int(region.state[i]) == 4)
        missed = int(region.missed.sum())
        console.print(f"  t {seconds:7.1f} s   {running}/{len(layout.owner_index)} running   "
                      f"{missed} missed deadlines", end="\r", highlight=False)
        time.sleep(every_s)
