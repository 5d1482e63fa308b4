"""The runs on this machine: a few at a time, each in its own child process (`runner.execute`), results
handed back as each finishes."""

from __future__ import annotations

from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor, as_completed

from hapticop.experiment.runner import execute, stop_all


def run_local(jobs: list[tuple[str, dict]], workers: int, time_limit_s: float) -> Iterator[tuple[str, dict]]:
    """(run id, job) in, (run id, outcome) out in the order they finish. Threads only wait: the work is in
    the children, so the GIL is never the limit. Closed before the end, it kills the runs in flight: their
    outcomes are never handed back, so they are run again on resume."""
    with ThreadPoolExecutor(max(1, workers)) as pool:
        futures = {pool.submit(execute, work, time_limit_s): run_id for run_id, work in jobs}
        try:
            for future in as_completed(futures):
                yield futures[future], future.result()
        finally:  # stopped early (Ctrl+C, an error): what has not started never does, what runs is killed
            for future in futures:
                future.cancel()
            stop_all()


