"""Named tables an experiment's report adds (`summaries:` in its file), in the form the README and the docs
have quoted since the hallway and delay studies were scripts: the same rows, computed from the table.

Each reads a row per run as the record the scripts kept: the factor columns by name, `metrics` (every
`metric.*` column) and `missed` (the targets the run's world judged missed)."""

from __future__ import annotations

import json
import math
import statistics
from collections import defaultdict
from collections.abc import Callable

PROFILES = ("cautious", "nominal", "aggressive", "tremor", "hands_off")
CONTROLS = ("operator alone", "shared control")
EMPTY_J = 1e-3
"""A tank this close to its floor counts as empty: it is (or was about to be) scaling the cue down."""
TANK_FLOOR_J = 0.0
"""The floor (`min_j`) of systems/teleop_sim.yaml's tank, which the delay experiment never varies (a test holds
the two together): the runs record the tank's lowest level, not its floor."""


def tank_empty(lowest_j: float | None, floor_j: float | None = TANK_FLOOR_J) -> bool | None:
    """Whether the tank ran empty: its lowest level within EMPTY_J of its floor, where it scales the cue down
    (None without a tank: no floor or no level)."""
    if floor_j is None or lowest_j is None:
        return None
    return lowest_j <= floor_j + EMPTY_J


def records(rows: list[dict]) -> list[dict]:
    out = []
    for row in rows:
        if row["status"] != "done":
            continue
        metrics = {k.removeprefix("metric."): v for k, v in row.items() if k.startswith("metric.")}
        missed = metrics.pop("missed", None)
        record = {k.removeprefix("factor."): v for k, v in row.items() if k.startswith("factor.")}
        out.append({**record, "seed": row["seed"], "metrics": metrics,
                    "missed": json.loads(missed) if isinstance(missed, str) else (missed or [])})
    return out


def _median(values: list, scale: float = 1.0, digits: int = 1) -> str:
    values = [v for v in values if v is not None]
    return f"{scale * statistics.median(values):.{digits}f}" if values else "-"


def hallway_sweep(rows: list[dict]) -> str:
    """A table per hallway, a row per operator profile and control: how many runs met each target and the
    spread of the metrics the targets judge (docs/hallway-experiment.md §12)."""
    runs = records(rows)
    out = []
    for hallway in sorted({r["hallway"] for r in runs}):
        out += [f"### {hallway}", "",
                "| operator | control | runs | all targets met | runs with collisions | stop error in target | "
                "stop error min / median / max (cm) | least side clearance min / median (m) | "
                "T/T_ref median / max | oscillation index max (m/s) | longest above 2 cm/s, max (s) | "
                "sustained oscillation (runs) | drift while stopped, max (cm/s) | force rate rms, max (N/s) | "
                "command changed > 10 %, median share | targets missed (runs) |",
                "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        here = [r for r in runs if r["hallway"] == hallway]
        for profile in PROFILES:
            for control in CONTROLS:
                group = [r for r in here if r["profile"] == profile and r["control"] == control]
                if group:
                    out.append(_sweep_row(profile, control, group))
        out.append("")
    return "\n".join(out)


def _sweep_row(profile: str, control: str, group: list[dict]) -> str:
    ms = [r["metrics"] for r in group]

    def values(key: str) -> list[float]:
        return [m[key] for m in ms if m.get(key) is not None]

    def spread(key: str, scale: float = 1.0, digits: int = 1, maximum: bool = True) -> str:
        v = values(key)
        if not v:
            return "-"
        return (f"{scale * min(v):.{digits}f} / {_median(v, scale, digits)}"
                + (f" / {scale * max(v):.{digits}f}" if maximum else ""))

    def largest(key: str, scale: float = 1.0, digits: int = 2) -> str:
        v = values(key)
        return f"{scale * max(v):.{digits}f}" if v else "-"

    missed: dict[str, int] = defaultdict(int)
    for r in group:
        for name in r["missed"]:
            missed[name.split(" (")[0]] += 1
    stop_ok = sum(1 for r in group if r["metrics"]["e_stop_m"] is not None
                  and not any("stop error" in m for m in r["missed"]))
    t_norm = values("t_norm")
    modified = values("frac_modified")
    cells = [profile, control, len(group), sum(1 for r in group if not r["missed"]),
             sum(1 for m in ms if m["n_collisions"]), stop_ok, spread("e_stop_m", 100),
             spread("side_clearance_min_m", digits=2, maximum=False),
             f"{_median(t_norm, digits=2)} / {max(t_norm):.2f}" if t_norm else "-",
             largest("oscillation_index_mps", digits=3), largest("oscillation_s"),
             sum(1 for m in ms if m["sustained_oscillation"]), largest("hold_speed_mps", 100),
             largest("force_rate_rms_nps", digits=1), _median(modified, digits=3) if modified else "-",
             ", ".join(f"{k} ({v})" for k, v in sorted(missed.items())) or "none"]
    return "| " + " | ".join(str(c) for c in cells) + " |"


def hallway_readme(rows: list[dict]) -> str:
    """The README's table: a row per hallway and control, every operator together, and which operators
    missed which target."""
    runs = records(rows)
    out = ["| hallway | control | runs | collisions | stops within -5/+10 cm | least side clearance (m) | "
           "T/T_ref, max | sustained oscillations | force rate rms, max (N/s) | every target met | "
           "targets missed: operator runs |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    for hallway in sorted({r["hallway"] for r in runs}):
        for control in CONTROLS:
            group = [r for r in runs if r["hallway"] == hallway and r["control"] == control]
            if not group:
                continue
            ms = [r["metrics"] for r in group]
            stops = sum(1 for m in ms if m["e_stop_m"] is not None and -0.05 <= m["e_stop_m"] <= 0.10)
            sides = [m["side_clearance_min_m"] for m in ms if m["side_clearance_min_m"] is not None]
            t_norm = [m["t_norm"] for m in ms if m.get("t_norm") is not None]
            rates = [m["force_rate_rms_nps"] for m in ms if m.get("force_rate_rms_nps") is not None]
            missed: dict[str, dict[str, int]] = defaultdict(lambda: defaultdict(int))
            for r in group:
                for name in r["missed"]:
                    missed[name.split(" (")[0]][r["profile"]] += 1
            cells = [hallway, control, len(group), sum(1 for m in ms if m["n_collisions"]), stops,
                     f"{min(sides):.2f}" if sides else "-", f"{max(t_norm):.2f}" if t_norm else "-",
                     sum(1 for m in ms if m["sustained_oscillation"]), f"{max(rates):.1f}" if rates else "-",
                     sum(1 for r in group if not r["missed"]),
                     "; ".join(f"{target}: " + ", ".join(f"{p} {n}" for p, n in sorted(who.items()))
                               for target, who in sorted(missed.items())) or "none"]
            out.append("| " + " | ".join(str(c) for c in cells) + " |")
    return "\n".join(out) + "\n"


def _delay(rows: list[dict], goal_only: bool) -> str:
    """A row per cell of the delay experiment (docs/teleop.md); `goal_only`: governor and tank on, 5 % loss."""
    runs = records(rows)
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for run in runs:
        rtt, loss = int(run["rtt_ms"]), float(run["loss"].rstrip(" %")) / 100
        governor, tank = run["governor"] == "on", run["tank"] == "on"
        if goal_only and not (loss == 0.05 and tank and governor):
            continue
        groups[(not governor, not tank, -loss, rtt)].append(run)
    lines = ["| governor | tank | loss | RTT (ms) | operators | runs with collisions | crashes | "
             "stop error within -5/+10 cm | stop error min / median / max (cm) | T/T_ref median / max | "
             "sustained oscillation | oscillation index median / max (cm/s) | tank's lowest level (J) | "
             "tank empty | measured round trip max (ms) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for key in sorted(groups):
        group = groups[key]
        first = group[0]
        ms = [r["metrics"] for r in group]
        stops = [m["e_stop_m"] for m in ms if m["e_stop_m"] is not None and not math.isnan(m["e_stop_m"])]
        spread = f"{100 * min(stops):.1f} / {_median(stops, 100)} / {100 * max(stops):.1f}" if stops else "-"
        norms = [m["t_norm"] for m in ms if m["t_norm"] is not None and not math.isnan(m["t_norm"])]
        t_norm = f"{_median(norms, digits=2)} / {max(norms):.2f}" if norms else "-"
        osc = [m["oscillation_index_mps"] for m in ms]
        tanks = [m["tank_level_min_j"] for m in ms if m.get("tank_level_min_j") is not None]
        empty = [e for e in (m["tank_empty"] if m.get("tank_empty") is not None else
                             tank_empty(m.get("tank_level_min_j")) for m in ms) if e is not None]
        trips = [m["round_trip_max_s"] for m in ms if m.get("round_trip_max_s") is not None]
        lines.append(
            f"| {first['governor']} | {first['tank']} | {first['loss']} | {first['rtt_ms']} | {len(group)} | "
            f"{sum(1 for m in ms if m['n_collisions'])} | {sum(bool(m['crash']) for m in ms)} | "
            f"{sum(1 for s in stops if -0.05 <= s <= 0.10)} of {len(group)} | {spread} | {t_norm} | "
            f"{sum(1 for m in ms if m['sustained_oscillation'])} | "
            f"{_median(osc, 100)} / {100 * max(osc):.1f} | {f'{min(tanks):.3f}' if tanks else '-'} | "
            f"{f'{sum(bool(e) for e in empty)} of {len(empty)}' if empty else '-'} | "
            f"{f'{1000 * max(trips):.0f}' if trips else '-'} |")
    return "\n".join(lines) + "\n"


def delay(rows: list[dict]) -> str:
    return _delay(rows, goal_only=False)


def delay_goal(rows: list[dict]) -> str:
    return _delay(rows, goal_only=True)


SUMMARIES: dict[str, Callable[[list[dict]], str]] = {
    "hallway_sweep": hallway_sweep, "hallway_readme": hallway_readme, "delay": delay, "delay_goal": delay_goal}
