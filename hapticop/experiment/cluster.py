"""The runs on a Ray cluster: each a task declaring its CPUs, streamed back with `ray.wait` as each finishes.
A task calls `runner.execute`, the very function the local pool calls, so a run gives the same numbers on
either.

A task lost with its worker or node is submitted again here (Ray places it on that node or another), up
to `retries` times, rather than by Ray's own retries: so the study knows, says so as it happens, and the
run's row keeps how many tries it took and what was lost. A run that fails by itself (a crash, a hang, a
refusal) is a failed row from `execute`, the same as on the pool, and is not tried again."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator


def _say(text: str) -> None:
    sys.stderr.write(text + "\n")
    sys.stderr.flush()


def run_ray(jobs: list[tuple[str, dict]], address: str, time_limit_s: float, cpus: float,
            retries: int, say: Callable[[str], None] = _say) -> Iterator[tuple[str, dict]]:
    try:
        import ray
    except ImportError as error:
        raise RuntimeError("--ray needs Ray: pip install 'hapticop[cluster]'") from error
    from hapticop.experiment.runner import execute

    started_here = not ray.is_initialized()
    if started_here:
        ray.init(address=None if address == "local" else address, include_dashboard=False,
                 log_to_driver=False, ignore_reinit_error=True)
    task = ray.remote(num_cpus=cpus, max_retries=0)(execute)
    lost: dict[str, list[str]] = {}
    pending = {task.remote(work, time_limit_s): (run_id, work) for run_id, work in jobs}
    try:
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            for ref in ready:
                run_id, work = pending.pop(ref)
                try:
                    outcome = ray.get(ref)
                except Exception as error:  # noqa: BLE001 - a task lost (its worker, its node): tried again
                    first = str(error).strip().splitlines()[0] if str(error).strip() else ""
                    lost.setdefault(run_id, []).append(f"{type(error).__name__}: {first}"[:300])
                    tries = len(lost[run_id])
                    if tries <= retries:
                        say(f"run {run_id} lost on the cluster ({type(error).__name__}), "
                            f"trying again ({tries + 1} of {retries + 1})")
                        pending[task.remote(work, time_limit_s)] = (run_id, work)
                        continue
                    say(f"run {run_id} lost on the cluster {tries} times: recorded as failed")
                    outcome = {"status": "failed", "message": f"lost on the cluster {tries} times: "
                               + "; ".join(lost[run_id]), "wall_s": 0.0, "composition_hash": "", "metrics": {}}
                    yield run_id, {**outcome, "tries": tries}
                    continue
                earlier = lost.get(run_id, [])
                if earlier and outcome["status"] == "done":
                    outcome["message"] = f"done at try {len(earlier) + 1}; lost before: " + "; ".join(earlier)
                yield run_id, {**outcome, "tries": len(earlier) + 1}
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)
        if started_here:
            ray.shutdown()
