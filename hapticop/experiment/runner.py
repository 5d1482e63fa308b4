"""One run: the composition with the run's patch, run to its end under the experiment's clock, its metrics
back. Each run is a child process of its own (`python -m hapticop.experiment.runner`, the job as JSON on
its standard input): a run that crashes takes nothing else with it, and one that hangs is killed with
its whole process group when its time is up. The pool and the Ray tasks both call `execute`, so a run
is the same computation wherever it runs.

A study stopped (Ctrl+C, SIGTERM) kills the runs in flight (`stop_all`); a study killed outright
(SIGKILL, a lost Ray worker) leaves its runs without their parent, and each run then kills its own
process group (`_orphan_watch`): nothing is left running for a study that is gone."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

RESULT_MARK = "@@hapticop-experiment-result "
ORPHAN_POLL_S = 0.5
_live: set[subprocess.Popen] = set()
_live_lock = threading.Lock()


PATH_STEP_S = 0.1
"""A kept path's sampling: enough to draw a run, small enough for a row."""


def job(composition: Path, patches: tuple, sets: tuple, seed: int, clock: str, duration_s: float | None,
        metrics: list[str] | None, path: bool = False) -> dict:
    return {"composition": str(composition), "patches": list(patches), "sets": [list(s) for s in sets], "seed": seed,
            "clock": clock, "duration_s": duration_s, "metrics": metrics, "path": path}


def execute(work: dict, time_limit_s: float) -> dict:
    """The run in a child process: `{status, message, wall_s, composition_hash, metrics}`; never raises for
    what the run did (a crash, a hang, a refusal are a failed row)."""
    started = time.perf_counter()
    child = subprocess.Popen([sys.executable, "-m", "hapticop.experiment.runner", str(os.getpid())],
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             start_new_session=True)
    with _live_lock:
        _live.add(child)
    try:
        out, err = child.communicate(json.dumps(work), timeout=time_limit_s)
    except subprocess.TimeoutExpired:
        _kill_group(child)
        return {"status": "failed", "message": f"time limit: still running after {time_limit_s:g} s, killed",
                "wall_s": time.perf_counter() - started, "composition_hash": digest_of(work), "metrics": {}}
    finally:
        _kill_group(child)  # whatever the run left behind in its group
        with _live_lock:
            _live.discard(child)
    wall = time.perf_counter() - started
    for line in reversed(out.splitlines()):
        if line.startswith(RESULT_MARK):
            return {**json.loads(line[len(RESULT_MARK):]), "wall_s": wall}
    tail = (err.strip().splitlines() or [f"exit status {child.returncode}"])[-1]
    return {"status": "failed", "message": f"the run's process ended without a result: {tail}",
            "wall_s": wall, "composition_hash": digest_of(work), "metrics": {}}


def stop_all() -> None:
    """Kill every run in flight in this process, with its process group (the study is stopping)."""
    with _live_lock:
        children = list(_live)
    for child in children:
        try:
            os.killpg(child.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass


def _kill_group(child: subprocess.Popen) -> None:
    try:
        os.killpg(child.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    child.wait()


def compose(work: dict):
    """The run's composition: the file, the experiment's patch, each factor's value set; and its digest."""
    import hashlib

    from hapticop.blocks.registry import search_beside
    from hapticop.composition.layers import resolve
    from hapticop.composition.yamlsource import Source, read_file
    from hapticop.experiment.grid import setting
    from hapticop.validation.patches import apply_patch

    search_beside(work["composition"])  # its own blocks may sit beside it
    source = resolve(read_file(work["composition"]))
    tree = source.tree
    for patch in work["patches"]:
        tree = apply_patch(tree, patch)
    tree = setting(tree, work["sets"])
    digest = hashlib.sha256(json.dumps(tree, sort_keys=True, default=str).encode()).hexdigest()[:16]
    return Source(source.file, tree, source.text), digest


def digest_of(work: dict) -> str:
    try:
        return compose(work)[1]
    except Exception:  # noqa: BLE001 - a composition that cannot be made has no digest; its row says why
        return ""


def run_here(work: dict) -> dict:
    """The run in this process (the child's side): validated as `hapticop validate` would, then run."""
    from hapticop.runtime.system import RunOptions, run_system
    from hapticop.validation import validate_source

    source, digest = compose(work)
    validated = validate_source(source)
    if not validated.report.ok:
        return {"status": "failed", "message": validated.report.errors[0].to_text().splitlines()[0],
                "composition_hash": digest, "metrics": {}}
    duration = None if work["duration_s"] is None else int(work["duration_s"] * 1e9)
    with tempfile.TemporaryDirectory() as run_dir:
        result = run_system(validated, RunOptions(clock=work["clock"], seed=work["seed"], run_dir=Path(run_dir),
                                                  echo=False, duration_ns=duration))
        found = Path(run_dir) / "metrics.json"
        metrics: dict[str, Any] = json.loads(found.read_text()) if found.exists() else {}
        judged = Path(run_dir) / "results.json"
        if judged.exists():  # the targets the world judged the run to miss
            metrics["missed"] = [r["metric"] for r in json.loads(judged.read_text())["rows"] if r["ok"] is False]
        path = _path(Path(run_dir) / "trajectory.npz") if work.get("path") else None
    wanted = work["metrics"]
    if wanted is not None:
        metrics = {name: metrics.get(name) for name in wanted}
    outcome = result.outcome
    failed = int(outcome.status) != 0
    return {"status": "failed" if failed else "done",
            "message": f"{outcome.status.name}: {'; '.join(outcome.reasons)}" if failed else "",
            "composition_hash": digest, "metrics": metrics, **({"path": path} if path else {})}


def _path(trajectory: Path) -> list[list[float]] | None:
    """The robot's x and y every PATH_STEP_S from the trajectory its world wrote (None without one)."""
    if not trajectory.exists():
        return None
    import numpy as np

    with np.load(trajectory) as data:
        if "t" not in data or "pose" not in data:
            return None
        t, pose = data["t"], data["pose"]
    if len(t) == 0:
        return None
    picked = np.searchsorted(t, np.arange(t[0], t[-1], PATH_STEP_S))
    picked = np.append(picked, len(t) - 1)
    return [pose[picked, 0].round(4).tolist(), pose[picked, 1].round(4).tolist()]


def _orphan_watch(parent: int) -> None:
    """The run's side: once the process that started it is gone (even before this began to watch), kill
    the run's whole group (itself too)."""
    while os.getppid() == parent:
        time.sleep(ORPHAN_POLL_S)
    os.killpg(0, signal.SIGKILL)


def main() -> None:
    if len(sys.argv) > 1 and os.getpgid(0) == os.getpid():  # started by `execute`, a group of its own
        threading.Thread(target=_orphan_watch, args=(int(sys.argv[1]),), daemon=True, name="orphan-watch").start()
    work = json.loads(sys.stdin.read())
    try:
        outcome = run_here(work)
    except Exception as error:  # noqa: BLE001 - the run's failure is a row of the table, not this process's
        outcome = {"status": "failed", "message": f"{type(error).__name__}: {error}", "composition_hash": "",
                   "metrics": {}}
    sys.stdout.write("\n" + RESULT_MARK + json.dumps(outcome, default=str) + "\n")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
