"""The runs on a Ray cluster: each a task declaring its CPUs, retried when its worker or node is lost,
streamed back with `ray.wait` as each finishes. A task calls `runner.execute`, the very function the local
pool calls, so a run gives the same numbers on either."""

from __future__ import annotations

from collections.abc import Iterator


def run_ray(jobs: list[tuple[str, dict]], address: str, time_limit_s: float, cpus: float,
            retries: int) -> Iterator[tuple[str, dict]]:
    try:
        import ray
    except ImportError as error:
        raise RuntimeError("--ray needs Ray: pip install 'hapticop[cluster]'") from error
    from hapticop.experiment.runner import execute

    started_here = not ray.is_initialized()
    if started_here:
        ray.init(address=None if address == "local" else address, include_dashboard=False,
                 log_to_driver=False, ignore_reinit_error=True)
    task = ray.remote(num_cpus=cpus, max_retries=retries, retry_exceptions=False)(execute)
    pending = {task.remote(work, time_limit_s): run_id for run_id, work in jobs}
    try:
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            for ref in ready:
                run_id = pending.pop(ref)
                try:
                    yield run_id, ray.get(ref)
                except Exception as error:  # noqa: BLE001 - a task lost for good (its node, its retries) is a failed row
                    yield run_id, {"status": "failed", "message": f"lost on the cluster: {type(error).__name__}: "
                                   f"{str(error).splitlines()[0] if str(error) else ''}", "wall_s": 0.0,
                                   "composition_hash": "", "metrics": {}}
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)
        if started_here:
            ray.shutdown()
