"""The live view's cost: the hallway in real time with and without `--view`, a client watching.

Runs `hapticop compose systems/bench.yaml` (the hallway for a fixed time, with its latency
probes) alternately without and with `--view`, one after the other on the same machine. With the
view, a Foxglove WebSocket client in this process (the `websockets` package, loopback) subscribes
to every channel the server advertises and counts what arrives, as Foxglove would. Each run's
timing.json gives the 1 kHz loops' wake-up latency p99 and missed deadlines; the run's own
report gives the CPU of the process that drains the rings and serves the view (all its
threads, the SDK's server included). Results are appended as JSON lines; `--summary` prints
the table. `--record` records both conditions to a file, for the view's cost beside a recorder
(the recorder's CPU without the view is then read from the file's metadata).

    python bench/liveview.py --runs 3 --duration 30s
    python bench/liveview.py --runs 3 --duration 30s --record
    python bench/liveview.py --summary
"""

from __future__ import annotations

import argparse
import asyncio
import json
import re
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from hapticop.benchmark.stats import spread_text

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "bench" / "results" / "liveview.jsonl"
COMPOSITION = ROOT / "systems" / "bench.yaml"
FAST_THREADS = ("main", "fieldbus", "watchdog")  # the application's 1 kHz loops
VIEW_CPU = re.compile(r"live view: \S+, (\d+) messages sent; its process used ([\d.]+) % of a core")


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def layout_topics() -> set[str]:
    """The topics the shipped hallway layout shows: what Foxglove subscribes to with it open."""
    layout = json.loads((ROOT / "foxglove-layouts" / "hallway.json").read_text())

    def panels(content):
        yield content
        for item in content.get("items", []):
            yield from panels(item["content"])

    topics = {"/tf"}  # the 3D panel's frames
    for panel in panels(layout["content"]):
        config = panel.get("config", {})
        topics |= set(config.get("topics", {})) | {p["value"].split(".")[0] for p in config.get("paths", [])}
        if config.get("topicToRender"):
            topics.add(config["topicToRender"])
    return topics


async def _watch(port: int, run_dir: Path, counts: dict, stop: threading.Event, only: set[str] | None = None) -> None:
    """Connect as soon as the server listens (with the token the run writes to its run directory, as
    its owner would), subscribe to every channel (or those `only` names), count messages by topic."""
    from websockets.asyncio.client import connect

    token_file = run_dir / f"live-view-{port}.token"
    while not stop.is_set():
        try:
            token = token_file.read_text().strip()
            socket_ = await connect(f"ws://127.0.0.1:{port}/?token={token}", subprotocols=["foxglove.sdk.v1"],
                                    max_size=None)
            break
        except OSError:
            await asyncio.sleep(0.1)
    else:
        return
    topics: dict[int, str] = {}
    async with socket_:
        try:
            async for frame in socket_:
                if isinstance(frame, str):
                    op = json.loads(frame)
                    if op["op"] == "advertise":
                        subscriptions = []
                        for channel in op["channels"]:
                            if only is not None and channel["topic"] not in only:
                                continue
                            topics[len(topics) + 1] = channel["topic"]
                            subscriptions.append({"id": len(topics), "channelId": channel["id"]})
                        await socket_.send(json.dumps({"op": "subscribe", "subscriptions": subscriptions}))
                else:
                    topic = topics[int.from_bytes(frame[1:5], "little")]
                    arrived = time.monotonic_ns()
                    count, first, _ = counts.get(topic, (0, arrived, arrived))
                    counts[topic] = (count + 1, first, arrived)
        except Exception:  # noqa: BLE001 - the run ended: the server closed the connection
            pass


def run(duration: str, viewed: bool, recorded: bool = False, layout: bool = False, rate: float | None = None) -> dict:
    with tempfile.TemporaryDirectory(prefix="hapticop-bench-view-") as scratch:
        run_dir = Path(scratch) / "run"
        command = [sys.executable, "-m", "hapticop.cli", "compose", str(COMPOSITION), "--duration", duration,
                   "--run-dir", str(run_dir)]
        if recorded:
            command += ["--record", str(Path(scratch) / "bench.mcap")]
        counts: dict[str, tuple[int, int, int]] = {}  # topic -> messages, first and last arrival (ns)
        stop = threading.Event()
        if viewed:
            port = _free_port()
            command += ["--view", str(port)] + (["--view-rate", f"{rate:g}"] if rate else [])
            only = layout_topics() if layout else None
            watch = _watch(port, run_dir, counts, stop, only)
            client = threading.Thread(target=lambda: asyncio.run(watch), daemon=True)
            client.start()
        process = subprocess.Popen(command, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        _, errors = process.communicate()
        stop.set()
        timing = json.loads((run_dir / "timing.json").read_text())
        row = {"viewed": viewed, "recorded": recorded, "subscribed": "layout" if layout else "all", "rate_hz": rate,
               "duration": duration, "exit": process.returncode,
               "loops_cpu_percent": timing["cpu"]["loops_percent"], "threads": {}}
        for name in FAST_THREADS:
            thread = timing["threads"][name]
            row["threads"][name] = {"cycles": thread["cycles"], "missed": thread["missed_deadlines"],
                                    "p50_us": thread["wakeup_latency_us"]["p50"],
                                    "p99_us": thread["wakeup_latency_us"]["p99"],
                                    "max_us": thread["wakeup_latency_us"]["max"]}
        if viewed:
            client.join(timeout=10)
            found = VIEW_CPU.search(errors)
            row.update({"view_cpu_percent": float(found.group(2)) if found else None,
                        "sent": int(found.group(1)) if found else None,
                        "received": sum(n for n, _, _ in counts.values()), "channels_received": len(counts),
                        "most_per_channel_hz": _busiest_hz(counts)})
        if recorded:
            from hapticop.recording.reading import contents

            recorder = contents(Path(scratch) / "bench.mcap").metadata.get("hapticop.recorder", {})
            row["recorder_cpu_percent"] = 100 * float(recorder["cpu_s"]) / float(recorder["elapsed_s"])
        if process.returncode != 0 or (viewed and not found):
            row["stderr"] = errors[-2000:]
        return row


def _busiest_hz(counts: dict[str, tuple[int, int, int]]) -> float:
    """The most messages a second one channel (the log aside) sent, over the time the client received."""
    start = min(first for _, first, _ in counts.values())
    end = max(last for _, _, last in counts.values())
    return max(n for topic, (n, _, _) in counts.items() if topic != "/log") / ((end - start) / 1e9)



def summary(rows: list[dict]) -> str:
    """A table per session kind: with or without a recording, what the client subscribed to, the view's rate."""
    def kind(row: dict) -> tuple:
        return row.get("recorded", False), row.get("subscribed", "all"), row.get("rate_hz")

    kinds = list(dict.fromkeys(kind(r) for r in rows))
    return "\n\n".join(_table([r for r in rows if kind(r) == k], *k) for k in kinds
                       if any(r["viewed"] for r in rows if kind(r) == k))


def _table(rows: list[dict], recorded: bool, subscribed: str, rate_hz: float | None) -> str:
    failed = [r for r in rows if r["exit"] != 0]  # a run that did not finish well measures nothing
    off, on = ([r for r in rows if r["viewed"] is flag and r["exit"] == 0] for flag in (False, True))
    also = (" --record" if recorded else "") + (f" --view-rate {rate_hz:g}" if rate_hz else "")
    whom = "every channel" if subscribed == "all" else "the hallway layout's channels"
    recording = " --record" if recorded else ""
    lines = [f"| | without --view{recording} | with --view{also}, a client subscribed to {whom} |",
             "| --- | --- | --- |",
             f"| runs | {len(off)} | {len(on)} |"]
    if failed:
        lines.append(f"| runs left out (exit status not 0) | {sum(not r['viewed'] for r in failed)} | "
                     f"{sum(r['viewed'] for r in failed)} |")
    for name in FAST_THREADS:
        for key, label in (("p99_us", "wake-up p99 µs"), ("max_us", "wake-up max µs"), ("missed", "missed deadlines")):
            lines.append(f"| {name} {label} | {spread_text([r['threads'][name][key] for r in off])} | "
                         f"{spread_text([r['threads'][name][key] for r in on])} |")
    lines.append(f"| loops' CPU % of a core | {spread_text([r['loops_cpu_percent'] for r in off])} | "
                 f"{spread_text([r['loops_cpu_percent'] for r in on])} |")
    if recorded:
        lines.append(f"| recorder process CPU % of a core | {spread_text([r['recorder_cpu_percent'] for r in off])} | "
                     f"{spread_text([r['recorder_cpu_percent'] for r in on])} |")
    for key, label in (("view_cpu_percent", "view process CPU % of a core"), ("received", "messages received"),
                       ("channels_received", "channels received"),
                       ("most_per_channel_hz", "busiest channel but the log, Hz")):
        lines.append(f"| {label} | | {spread_text([r[key] for r in on])} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=0, help="pairs of runs, without and with the live view")
    parser.add_argument("--duration", default="30s")
    parser.add_argument("--record", action="store_true", help="both conditions also record to a file")
    parser.add_argument("--rate", type=float, default=None, help="the view's --view-rate (default: its own)")
    parser.add_argument("--layout", action="store_true",
                        help="the client subscribes to the shipped layout's channels only, as Foxglove with it open")
    parser.add_argument("--summary", action="store_true")
    args = parser.parse_args()
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    for index in range(args.runs):  # alternate which goes first, so drifting load hits both alike
        for viewed in ((False, True) if index % 2 == 0 else (True, False)):
            row = run(args.duration, viewed, args.record, args.layout, args.rate)
            row["at"] = time.strftime("%Y-%m-%dT%H:%M:%S")
            with open(RESULTS, "a") as out:
                out.write(json.dumps(row) + "\n")
            print(json.dumps(row), flush=True)
    if args.summary:
        rows = [json.loads(line) for line in RESULTS.read_text().splitlines()] if RESULTS.exists() else []
        print(summary(rows))


if __name__ == "__main__":
    main()
