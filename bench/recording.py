"""The recorder's cost and losses: the hallway in real time with and without `--record`.

Runs `hapticop compose systems/bench.yaml` (the hallway for a fixed time, with its latency
probes) alternately without and with the recorder, one after the other on the same machine,
and reads each run's timing.json (wake-up latency p99 and missed deadlines of the 1 kHz loops)
and recording (samples, drops, bytes per sample, the recorder's own CPU time). `--kill` then
runs it with the recorder and SIGKILLs every process of the run at once (the resource tracker
aside, so the shared memory is still released), recovers the `.part` and measures how much
recorded time the kill lost: from the last sample in the file to the kill, on CLOCK_MONOTONIC,
the recording's own clock. Results are appended as JSON lines; `--summary` prints the table.

    python bench/recording.py --runs 3 --duration 30s --kill 3
    python bench/recording.py --long 600s       # one long recorded run, for drops
    python bench/recording.py --summary
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from hapticop.benchmark.stats import spread_text

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "bench" / "results" / "recording.jsonl"
COMPOSITION = ROOT / "systems" / "bench.yaml"
FAST_THREADS = ("main", "fieldbus", "watchdog")  # the application's 1 kHz loops


def _compose(run_dir: Path, duration: str, record: Path | None, **popen) -> subprocess.Popen:
    command = [sys.executable, "-m", "hapticop.cli", "compose", str(COMPOSITION), "--duration", duration,
               "--run-dir", str(run_dir)]
    if record is not None:
        command += ["--record", str(record)]
    return subprocess.Popen(command, cwd=ROOT, stdout=subprocess.DEVNULL, text=True, **popen)


def _recording(path: Path) -> dict:
    from hapticop.recording.reading import contents

    found = contents(path)
    recorder = found.metadata.get("hapticop.recorder", {})
    streams = [c.stream for c in found.channels if c.stream is not None]
    fast = sum(1 for s in streams if s.rate_hz >= 999)
    messages = sum(c.count for c in found.channels)
    cpu_s, elapsed_s = float(recorder.get("cpu_s", "nan")), float(recorder.get("elapsed_s", "nan"))
    return {"messages": messages, "drops": sum(found.drops().values()), "streams": len(streams),
            "fast_streams": fast, "bytes": path.stat().st_size, "bytes_per_sample": path.stat().st_size / messages,
            "recorder_cpu_percent": 100 * cpu_s / elapsed_s,
            "recorder_cpu_percent_per_fast_stream": 100 * cpu_s / elapsed_s / max(fast, 1)}


def run(duration: str, recorded: bool) -> dict:
    with tempfile.TemporaryDirectory(prefix="hapticop-bench-rec-") as scratch:
        run_dir = Path(scratch) / "run"
        target = Path(scratch) / "bench.mcap" if recorded else None
        process = _compose(run_dir, duration, target, stderr=subprocess.PIPE)
        _, errors = process.communicate()
        timing = json.loads((run_dir / "timing.json").read_text())
        row = {"kind": "run", "recorded": recorded, "duration": duration, "exit": process.returncode,
               "loops_cpu_percent": timing["cpu"]["loops_percent"], "threads": {}}
        for name in FAST_THREADS:
            thread = timing["threads"][name]
            row["threads"][name] = {"cycles": thread["cycles"], "missed": thread["missed_deadlines"],
                                    "p50_us": thread["wakeup_latency_us"]["p50"],
                                    "p99_us": thread["wakeup_latency_us"]["p99"]}
        if target is not None:
            row.update(_recording(target))
        if process.returncode != 0:
            row["stderr"] = errors[-2000:]
        return row


def _session(pid: int) -> list[int]:
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                if os.getsid(int(entry)) == pid:
                    found.append(int(entry))
            except OSError:
                continue
    return found


def _cmdline(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as cmdline:
            return cmdline.read().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def kill(after_s: float) -> dict:
    """SIGKILL of the whole run `after_s` seconds into its recording, then `hapticop recover`."""
    from hapticop.recording.reading import series
    from hapticop.recording.recover import recover

    with tempfile.TemporaryDirectory(prefix="hapticop-bench-kill-") as scratch:
        target = Path(scratch) / "bench.mcap"
        part = target.with_name(target.name + ".part")
        process = _compose(Path(scratch) / "run", "120s", target, start_new_session=True, stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not (part.exists() and part.stat().st_size > 200_000):
            time.sleep(0.05)  # the loops run: the first samples were flushed
        time.sleep(after_s)
        victims = [p for p in _session(process.pid) if "resource_tracker" not in _cmdline(p)]
        killed_ns = time.monotonic_ns()
        for pid in victims:
            os.kill(pid, signal.SIGKILL)
        process.wait(timeout=30)
        size = part.stat().st_size
        found = recover(part)
        main = series(found.target, "handle_force")
        last_log = max(int(main.log_ns[-1]), found.last_ns)
        return {"kind": "kill", "after_s": after_s, "part_bytes": size, "lost_bytes": found.lost_bytes,
                "recovered_messages": sum(found.messages.values()),
                "lost_s": (killed_ns - last_log) / 1e9,
                "lost_publish_s": (killed_ns - int(main.publish_ns[-1])) / 1e9,
                "contiguous": bool((main.sequence[1:] - main.sequence[:-1] == 1).all())}



def summary(rows: list[dict]) -> str:
    lines = ["| | without recorder | with recorder |", "| --- | --- | --- |"]
    runs = [r for r in rows if r["kind"] == "run" and r["duration"] != "long"]
    off, on = ([r for r in runs if r["recorded"] is flag] for flag in (False, True))
    lines.append(f"| runs | {len(off)} | {len(on)} |")
    for name in FAST_THREADS:
        for key, label in (("p99_us", "wake-up p99 µs"), ("missed", "missed deadlines")):
            lines.append(f"| {name} {label} | {spread_text([r['threads'][name][key] for r in off])} | "
                         f"{spread_text([r['threads'][name][key] for r in on])} |")
    lines.append(f"| loops' CPU % of a core | {spread_text([r['loops_cpu_percent'] for r in off])} | "
                 f"{spread_text([r['loops_cpu_percent'] for r in on])} |")
    for key, label in (("recorder_cpu_percent", "recorder CPU % of a core"),
                       ("recorder_cpu_percent_per_fast_stream", "recorder CPU % per 1 kHz stream"),
                       ("bytes_per_sample", "bytes per sample (zstd)"), ("messages", "samples recorded"),
                       ("drops", "samples dropped")):
        lines.append(f"| {label} | | {spread_text([r[key] for r in on])} |")
    for r in rows:
        if r["kind"] == "run" and r["duration"] == "long":
            lines.append(f"\nlong run ({r['long']}): {r['messages']} samples, {r['drops']} dropped, recorder "
                         f"{r['recorder_cpu_percent']:.2f} % of a core")
    kills = [r for r in rows if r["kind"] == "kill"]
    if kills:
        lost_s = spread_text([r['lost_s'] for r in kills])
        lines.append(f"\nkill -9 of the whole run ({len(kills)} times): lost {lost_s}"
                     f" s of log time, {spread_text([r['lost_bytes'] for r in kills])} bytes cut; "
                     f"every recovered stream contiguous: {all(r['contiguous'] for r in kills)}")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=0, help="pairs of runs, without and with the recorder")
    parser.add_argument("--duration", default="30s")
    parser.add_argument("--kill", type=int, default=0, help="runs killed with SIGKILL and recovered")
    parser.add_argument("--long", default=None, help="one recorded run this long (e.g. 600s)")
    parser.add_argument("--summary", action="store_true")
    args = parser.parse_args()
    RESULTS.parent.mkdir(parents=True, exist_ok=True)

    def keep(row: dict) -> None:
        row["at"] = time.strftime("%Y-%m-%dT%H:%M:%S")
        with open(RESULTS, "a") as out:
            out.write(json.dumps(row) + "\n")
        print(json.dumps(row), flush=True)

    for index in range(args.runs):  # alternate which goes first, so drifting load hits both alike
        for recorded in ((False, True) if index % 2 == 0 else (True, False)):
            keep(run(args.duration, recorded))
    for _ in range(args.kill):
        keep(kill(after_s=10.0))
    if args.long:
        row = run(args.long, True)
        row["long"], row["duration"] = args.long, "long"
        keep(row)
    if args.summary:
        rows = [json.loads(line) for line in RESULTS.read_text().splitlines()] if RESULTS.exists() else []
        print(summary(rows))


if __name__ == "__main__":
    main()
