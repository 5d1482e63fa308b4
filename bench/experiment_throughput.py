"""Runs per minute of one experiment on the local pool and on a local Ray cluster, interleaved, and Ray's own
cost per task (an empty task's round trip). docs/experiments.md quotes what this prints.

    python bench/experiment_throughput.py --repeats 3 --workers 2
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import tempfile
import time
from pathlib import Path

from hapticop.experiment.checks import load
from hapticop.experiment.study import run_study

ROOT = Path(__file__).resolve().parent.parent
STUDY = ROOT / "tests" / "experiments" / "tiny.yaml"


def _noop() -> int:
    return 0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seeds", type=int, default=4, help="seeds per cell (two cells)")
    args = parser.parse_args()
    import ray

    loaded = load(STUDY)
    loaded.experiment.seeds.count = args.seeds
    runs = 2 * args.seeds
    rates: dict[str, list[float]] = {"pool": [], "ray": []}
    short = tempfile.mkdtemp(prefix="ray", dir="/tmp")
    ray.init(num_cpus=args.workers, include_dashboard=False, log_to_driver=False, _temp_dir=short)
    try:
        task = ray.remote(num_cpus=1)(_noop)
        ray.get([task.remote() for _ in range(20)])  # workers warm
        started = time.perf_counter()
        ray.get([task.remote() for _ in range(500)])
        per_task_ms = (time.perf_counter() - started) / 500 * 1000
        started = time.perf_counter()
        for _ in range(50):
            ray.get(task.remote())
        one_by_one_ms = (time.perf_counter() - started) / 50 * 1000
        for repeat in range(args.repeats):
            for backend in ("pool", "ray") if repeat % 2 == 0 else ("ray", "pool"):
                with tempfile.TemporaryDirectory() as out:
                    started = time.perf_counter()
                    done, failed = run_study(loaded, Path(out), workers=args.workers,
                                             ray="auto" if backend == "ray" else None)
                    minutes = (time.perf_counter() - started) / 60
                assert (done, failed) == (runs, 0), (done, failed)
                rates[backend].append(runs / minutes)
                print(f"{backend}: {runs / minutes:.1f} runs/min  (load {os.getloadavg()[0]:.2f})", flush=True)
    finally:
        ray.shutdown()
        shutil.rmtree(short, ignore_errors=True)
    print(f"\n{runs} runs of {STUDY.name} per repeat, {args.workers} workers/CPUs, {args.repeats} repeats, "
          f"load average now {os.getloadavg()}")
    for backend, values in rates.items():
        print(f"{backend}: runs/min min {min(values):.1f} / median {statistics.median(values):.1f} / max "
              f"{max(values):.1f}; per core {statistics.median(values) / args.workers:.1f} runs/min")
    print(f"ray empty task: {per_task_ms:.2f} ms each in a batch of 500, {one_by_one_ms:.2f} ms one at a time")


if __name__ == "__main__":
    main()
