"""The results as a Parquet dataset, one row a run: `OUT/parts/*.parquet` and `OUT/manifest.json`.

Every finished run is written at once as a part file of its own (renamed into place when complete), so a
crash or a kill loses at most the runs in flight; `read` concatenates the parts (pandas and polars read
the folder directly as one dataset). A failed run run again (`--retry-failed`) adds a row rather than
rewrite a part: `read` keeps one row per run, its done row if it has one, else its latest (the folder read
directly shows every try). The manifest names the experiment's meaning and the software version: a folder
written by another experiment or version is refused, never mixed in."""

from __future__ import annotations

import json
import os
import time
import uuid
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

MANIFEST = "manifest.json"
FIXED = ("run_id", "cell", "seed", "composition_hash", "software_version", "wall_s", "status", "message", "tries")


class TableMismatch(Exception):
    """The folder holds another experiment's or another version's runs."""


def open_table(out: Path, experiment: str, meaning: str, version: str) -> None:
    """Create the folder for this experiment, or check that it is this experiment's."""
    manifest = out / MANIFEST
    if manifest.exists():
        found = json.loads(manifest.read_text())
        if found.get("meaning") != meaning:
            raise TableMismatch(
                f"{out}: written by another experiment ({found.get('experiment')!r}, meaning {found.get('meaning')}; "
                f"this file's is {meaning}): give another --out, or move the old results away")
        if found.get("software_version") != version:
            raise TableMismatch(
                f"{out}: written by hapticop {found.get('software_version')}, this is {version}: results of two "
                "versions are not mixed; give another --out")
        return
    (out / "parts").mkdir(parents=True, exist_ok=True)
    _atomic(manifest, json.dumps({"experiment": experiment, "meaning": meaning, "software_version": version},
                                 indent=2) + "\n")


def _atomic(path: Path, text: str) -> None:
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_text(text)
    os.replace(temporary, path)


def row(run_id: str, cell: str, factors: dict[str, Any], seed: int, version: str, outcome: dict) -> dict:
    """A run's row: the fixed columns, `factor.NAME` per factor, `metric.NAME` per metric."""
    data = {"run_id": run_id, "cell": cell, "seed": seed, "composition_hash": outcome.get("composition_hash", ""),
            "software_version": version, "wall_s": float(outcome.get("wall_s", 0.0)), "status": outcome["status"],
            "message": outcome.get("message", ""), "tries": int(outcome.get("tries", 1))}
    if outcome.get("path"):  # the robot's path, [xs, ys] as JSON (`paths:` in the experiment file)
        data["path"] = json.dumps(outcome["path"])
    data |= {f"factor.{k}": v for k, v in factors.items()}
    for name, value in outcome.get("metrics", {}).items():
        data[f"metric.{name}"] = (json.dumps(value) if isinstance(value, dict | list) else
                                  float(value) if isinstance(value, int) and not isinstance(value, bool) else value)
    return data


def append(out: Path, rows: list[dict]) -> None:
    """Rows as one new part, whole or not at all."""
    if not rows:
        return
    name = out / "parts" / f"part-{time.time_ns():020d}-{uuid.uuid4().hex}.parquet"  # names sort as written
    temporary = name.with_suffix(".tmp")
    pq.write_table(pa.Table.from_pylist(rows), temporary)
    os.replace(temporary, name)


def _written(part: Path) -> int:
    """When a part was written, from its name (a part named before names carried it: the oldest)."""
    stamp = part.stem.split("-")[1]
    return int(stamp) if len(stamp) == 20 and stamp.isdigit() else 0


def read(out: Path) -> pa.Table:
    """Every run's row: the done one if a run has one, else the latest written."""
    parts = sorted((out / "parts").glob("*.parquet"), key=lambda p: (_written(p), p.name))
    if not parts:
        return pa.table({column: [] for column in FIXED})
    table = pa.concat_tables([pq.read_table(p) for p in parts], promote_options="permissive")
    statuses = table.column("status").to_pylist()
    kept: dict[str, int] = {}
    for i, run_id in enumerate(table.column("run_id").to_pylist()):
        if run_id not in kept or statuses[i] == "done" or statuses[kept[run_id]] != "done":
            kept[run_id] = i
    return table if len(kept) == table.num_rows else table.take(sorted(kept.values()))


def finished(out: Path, retry_failed: bool = False) -> set[str]:
    """The run ids not to run again: every run the table holds, or with `retry_failed` only those done."""
    if not (out / "parts").exists():
        return set()
    table = read(out)
    return {run_id for run_id, status in zip(table.column("run_id").to_pylist(), table.column("status").to_pylist())
            if status == "done" or not retry_failed}
