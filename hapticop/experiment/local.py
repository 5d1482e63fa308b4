"""The runs on this machine: a few at a time, each in its own child process (`runner.execute`), results
handed back as each finishes."""

from __future__ import annotations

from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor, as_completed

from hapticop.experiment.runner import execute


def run_local(jobs: list[tuple[str, dict]], workers: int, time_limit_s: float) -> Iterator[tuple[str, dict]]:
    """(run id, job) in, (run id, outcome) out in the order they finish. Threads only wait: the work is in
    the children, so the GIL is never the limit."""
    with ThreadPoolExecutor(max(1, workers)) as pool:
        futures = {pool.submit(execute, work, time_limit_s): run_id for run_id, work in jobs}
        try:
            for future in as_completed(futures):
                yield futures[future], future.result()
        finally:
            for future in futures:
                future.cancel()


