"""What crossing hosts costs: Zenoh's round trip against raw UDP between two network namespaces, and the
1 kHz loops' wake-up latency and misses with a bridge running beside them and without.

    sudo python bench/zenoh_link.py transport [--runs 3] [--count 3000]
    sudo python bench/zenoh_link.py loops [--runs 3] [--seconds 10] [--pin] [--low-latency]
    python bench/zenoh_link.py linkloss [--runs 3] [--seconds 10]
    sudo python bench/zenoh_link.py security [--runs 5] [--count 3000] [--seconds 10]

`transport` makes two namespaces joined by a veth and echoes 64-byte messages paced at 1 kHz, first over
Zenoh as a bridge uses it by default (peer mode, explicit endpoints, no scouting, express, REAL_TIME, a ring
channel of 1), then the same over Zenoh's low-latency transport (a host's `transport: low_latency`), then
over a plain UDP socket. `loops` runs a 1 kHz real-time loop whose samples cross to
a second host through the bridges, and the same loop and reader on one host without them. `linkloss`
kills the operator's side of systems/teleop.yaml after it has driven for a while and measures, on the
robot's recording, how long after the last setpoint's send time the robot stands still. `security` measures
what the secure link costs: in each run the round trip over the low-latency transport on plain TCP and on
mutual TLS with the access rules, then the 1 kHz loop beside an insecure and a secure bridge. Figures go to
bench/results/zenoh-link.json and docs/teleop.md; none is judged here.
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
PAYLOAD = bytes(64)
PORT = 7447


# -- the two ends, each run inside its namespace ------------------------------------------------
def _credentials(flags: list[str], me: str, other: str):
    """With 'tls=DIR': mutual TLS as a bridge uses it, `me` may be sent bench/`other`'s key and put its own."""
    from hapticop.network import keys, transport

    directory = next((Path(f.split("=", 1)[1]) for f in flags if f.startswith("tls=")), None)
    if directory is None:
        return None
    where = keys.files(directory, me)
    return transport.Credentials(str(where.ca), str(where.certificate), str(where.key),
                                 [transport.Rights(other, puts=[f"bench/{other}"], reads=[f"bench/{me}"])])


def echo_zenoh(listen: str, connect: str, flags: list[str] = ()) -> None:
    import zenoh

    from hapticop.network import transport

    with transport.session([listen], [connect], "low_latency" in flags, _credentials(flags, "pong", "ping")) as net:
        pong = net.declare_publisher("bench/pong", priority=zenoh.Priority.REAL_TIME, express=True)
        ping = net.declare_subscriber("bench/ping", zenoh.handlers.RingChannel(1))
        print("ready", flush=True)
        while True:
            pong.put(ping.recv().payload.to_bytes())


def ping_zenoh(listen: str, connect: str, count: int, flags: list[str] = ()) -> list[int]:
    import zenoh

    from hapticop.network import transport

    with transport.session([listen], [connect], "low_latency" in flags, _credentials(flags, "ping", "pong")) as net:
        ping = net.declare_publisher("bench/ping", priority=zenoh.Priority.REAL_TIME, express=True)
        pong = net.declare_subscriber("bench/pong", zenoh.handlers.RingChannel(1))
        for _ in range(100):  # until the echo answers (the peers have found each other)
            ping.put(PAYLOAD)
            time.sleep(0.1)
            if pong.try_recv() is not None:
                break
        while pong.try_recv() is not None:
            pass
        return _paced(count, lambda: ping.put(PAYLOAD), lambda: pong.recv())


def echo_udp(address: str) -> None:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind((address, PORT + 1))
    print("ready", flush=True)
    while True:
        data, peer = sock.recvfrom(2048)
        sock.sendto(data, peer)


def ping_udp(address: str, count: int) -> list[int]:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.settimeout(1.0)
    return _paced(count, lambda: sock.sendto(PAYLOAD, (address, PORT + 1)), lambda: sock.recv(2048))


def _paced(count: int, send, receive) -> list[int]:
    """Round trips in ns, one per millisecond (a 1 kHz setpoint stream's pace)."""
    rtts, next_ns = [], time.monotonic_ns()
    for _ in range(count):
        start = time.monotonic_ns()
        send()
        receive()
        rtts.append(time.monotonic_ns() - start)
        next_ns += 1_000_000
        delay = next_ns - time.monotonic_ns()
        if delay > 0:
            time.sleep(delay / 1e9)
    return rtts


# -- the harness ----------------------------------------------------------------------------------
def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True)


class Namespaces:
    """Two namespaces joined by a veth, 10.N.0.1 and 10.N.0.2, removed on exit."""

    def __init__(self) -> None:
        tag = os.getpid() % 100000
        self.a, self.b = f"zla{tag}", f"zlb{tag}"
        subnet = 10 + os.getpid() % 200
        self.addr_a, self.addr_b = f"10.{subnet}.0.1", f"10.{subnet}.0.2"
        self.veth = (f"zva{tag}", f"zvb{tag}")

    def __enter__(self) -> Namespaces:
        _ip("netns", "add", self.a)
        _ip("netns", "add", self.b)
        _ip("link", "add", self.veth[0], "type", "veth", "peer", "name", self.veth[1])
        for ns, dev, addr in ((self.a, self.veth[0], self.addr_a), (self.b, self.veth[1], self.addr_b)):
            _ip("link", "set", dev, "netns", ns)
            _ip("-n", ns, "addr", "add", f"{addr}/24", "dev", dev)
            _ip("-n", ns, "link", "set", dev, "up")
            _ip("-n", ns, "link", "set", "lo", "up")
        return self

    def __exit__(self, *_: object) -> None:
        for ns in (self.a, self.b):
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)

    def run(self, ns: str, *args: str, **kwargs) -> subprocess.Popen:
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        return subprocess.Popen(["ip", "netns", "exec", ns, "nice", "-n", "-5", sys.executable, __file__, *args],
                                env=env, text=True, stdout=subprocess.PIPE, **kwargs)


def percentiles(ns: list[int]) -> dict:
    us = np.asarray(ns) / 1e3
    return {"count": len(us), "p50_us": round(float(np.percentile(us, 50)), 1),
            "p99_us": round(float(np.percentile(us, 99)), 1), "p99.9_us": round(float(np.percentile(us, 99.9)), 1),
            "max_us": round(float(us.max()), 1)}


def transport_runs(runs: int, count: int) -> dict:
    """Each run measures the three in turn, so a busy spell of the machine touches them alike."""
    results = {"zenoh": [], "zenoh_low_latency": [], "udp": []}
    with Namespaces() as spaces:  # as a bridge measured before its link was secured: plain TCP
        zenoh_a, zenoh_b = f"tcp/{spaces.addr_a}:{PORT}", f"tcp/{spaces.addr_b}:{PORT}"
        for _ in range(runs):
            for kind, echo_args, ping_args in (
                    ("zenoh", ("echo-zenoh", zenoh_b, zenoh_a), ("ping-zenoh", zenoh_a, zenoh_b, str(count))),
                    ("zenoh_low_latency", ("echo-zenoh", zenoh_b, zenoh_a, "low_latency"),
                     ("ping-zenoh", zenoh_a, zenoh_b, str(count), "low_latency")),
                    ("udp", ("echo-udp", spaces.addr_b), ("ping-udp", spaces.addr_b, str(count)))):
                echo = spaces.run(spaces.b, *echo_args)
                try:
                    assert echo.stdout.readline().strip() == "ready"
                    pinger = spaces.run(spaces.a, *ping_args)
                    out, _ = pinger.communicate(timeout=120)
                    results[kind].append(percentiles(json.loads(out)))
                finally:
                    echo.kill()
                    echo.wait()
                print(kind, results[kind][-1], flush=True)
    return results


def security_transport(spaces: Namespaces, directory: Path, count: int) -> dict:
    """One round-trip run over the low-latency transport, plain TCP then mutual TLS with the access rules."""
    figures = {}
    for kind, scheme, flags in (("insecure", "tcp", ["low_latency"]),
                                ("secure", "tls", ["low_latency", f"tls={directory}"])):
        end_a, end_b = f"{scheme}/{spaces.addr_a}:{PORT}", f"{scheme}/{spaces.addr_b}:{PORT}"
        echo = spaces.run(spaces.b, "echo-zenoh", end_b, end_a, *flags)
        try:
            assert echo.stdout.readline().strip() == "ready"
            pinger = spaces.run(spaces.a, "ping-zenoh", end_a, end_b, str(count), *flags)
            out, _ = pinger.communicate(timeout=120)
            figures[kind] = percentiles(json.loads(out))
        finally:
            echo.kill()
            echo.wait()
    return figures


def security_runs(runs: int, count: int, seconds: int) -> dict:
    """Round trip and the loop's wake-up, insecure against secure, alternating within each run."""
    from hapticop.network import keys

    results: dict = {"round_trip": [], "loops": []}
    with tempfile.TemporaryDirectory() as tmp, Namespaces() as spaces:
        directory = Path(tmp)
        keys.make_ca(directory, "bench")
        keys.make_host(directory, "ping", [spaces.addr_a])
        keys.make_host(directory, "pong", [spaces.addr_b])
        for _ in range(runs):
            results["round_trip"].append(security_transport(spaces, directory, count))
            print("round trip", results["round_trip"][-1], flush=True)
            loops = {}
            for secure in (False, True):
                loops["secure" if secure else "insecure"] = loop_runs(1, seconds, low_latency=True,
                                                                      secure=secure)["with_bridge"][0]
            results["loops"].append(loops)
    return results


LOOP = """\
    version: 1
    name: zlink{tag}
    {security}
    {hosts}
    threads:
      main: {{period: 10ms, deploy: main, {host_a} schedules: {{0: [mediator]}}}}
      loop: {{period: 1ms, priority: 38, {host_a} {loop_cpus} schedules: {{0: [counter]}}}}
      {b_main}
      reader: {{period: 1ms, priority: 37, deploy: process, {host_b} schedules: {{0: [echo]}}}}
    activities:
      mediator: {{block: mediator}}
      counter: {{block: counter}}
      echo: {{block: echo}}
    streams:
      count:
        from: counter.count
        to: [echo.input]
        {network}
    """


def loop_runs(runs: int, seconds: int, pin: bool = False, low_latency: bool = False, secure: bool = False) -> dict:
    """With `pin`, the loop runs on the last core and the bridges on the first, in both cases; with
    `low_latency`, the hosts use Zenoh's low-latency transport; with `secure`, mutual TLS and access
    rules (else an insecure link, as these figures were first measured), and only with the bridge."""
    from hapticop.cli.hosts import keys_for

    results = {"with_bridge": [], "without": []} if not secure else {"with_bridge": []}
    scheme = "tls" if secure else "tcp"
    last = (os.cpu_count() or 1) - 1
    bridge_cpus = (", bridge_cpus: [0]" if pin else "") + (", transport: low_latency" if low_latency else "")
    with tempfile.TemporaryDirectory() as tmp:
        for run in range(runs):
            for kind in results:
                bridged = kind == "with_bridge"
                text = textwrap.dedent(LOOP).format(
                    tag=f"{os.getpid()}{run}{int(bridged)}",
                    security=("security: {keys: loop.keys}" if secure else "security: {insecure: true}")
                    if bridged else "",
                    hosts=f"hosts: {{a: {{endpoints: [{scheme}/127.0.0.1:17481]{bridge_cpus}}}, "
                    f"b: {{endpoints: [{scheme}/127.0.0.1:17482]{bridge_cpus}}}}}" if bridged else "",
                    loop_cpus=f"cpus: [{last}]," if pin else "",
                    host_a="host: a," if bridged else "", host_b="host: b," if bridged else "",
                    b_main="b_main: {period: 10ms, deploy: main, host: b, schedules: {0: [mediator]}}"
                    if bridged else "",
                    network="network: {priority: real_time, deadline: 100ms, stale: zero}" if bridged else "")
                path = Path(tmp) / f"{kind}{run}.yaml"
                path.write_text(text)
                if secure:
                    keys_for(path)
                run_dir = Path(tmp) / f"run-{kind}{run}"
                subprocess.run([sys.executable, "-m", "hapticop.cli", "compose", str(path), "--duration",
                                f"{seconds}s", "--run-dir", str(run_dir)], cwd=ROOT, capture_output=True,
                               env={**os.environ, "PYTHONPATH": str(ROOT)}, check=False)
                timing = json.loads(((run_dir / "a") if bridged else run_dir).joinpath("timing.json").read_text())
                figures = {}
                for thread in ("loop",) + (("bridge",) if bridged else ()):
                    t = timing["threads"][thread]
                    figures[thread] = {**t["wakeup_latency_us"], "missed": t["missed_deadlines"],
                                       "cycles": t["cycles"], "cpu_percent": t["cpu_percent"]}
                results[kind].append(figures)
                print(kind, figures, flush=True)
    return results


def linkloss_runs(runs: int, drive_s: float) -> dict:
    """The operator's side of systems/teleop.yaml killed while the robot drives: from the last setpoint's
    send time to the robot's top speed (where the deadman's zero setpoint starts its braking) and to the
    robot standing still."""
    from hapticop.recording.reading import series

    results = []
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    with tempfile.TemporaryDirectory() as tmp:
        for run in range(runs):
            base = Path(tmp) / f"run{run}"

            def side(host: str, *extra: str) -> subprocess.Popen:
                return subprocess.Popen([sys.executable, "-m", "hapticop.cli", "compose", "systems/teleop.yaml",
                                         "--host", host, "--run-dir", str(base / host), *extra], cwd=ROOT, env=env,
                                        start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

            robot = side("robot", "--record")
            operator = side("operator")
            operator_log = base / "operator" / "operator.log"
            while not (operator_log.exists() and "starts driving" in operator_log.read_text()):
                time.sleep(0.2)
            time.sleep(drive_s)
            os.killpg(operator.pid, 9)  # the operator's host dies without a word
            operator.wait()
            time.sleep(3.0)
            os.killpg(robot.pid, 2)
            robot.wait(timeout=120)
            recording = base / "robot" / "teleop_robot.mcap"
            setpoints = series(recording, "velocity_setpoint")
            twist = series(recording, "robot_twist")
            commands = series(recording, "platform_velocity")
            last_sent = int(setpoints.publish_ns[-1])
            moving = np.abs(twist.values[:, 0]) > 0.01
            after = twist.publish_ns > last_sent
            still = np.flatnonzero(after & ~moving)
            speed = float(np.abs(twist.values[after][0, 0])) if after.any() else 0.0
            speeds = np.where(after, np.abs(twist.values[:, 0]), -1.0)
            # the last sample at its top speed: the robot held it (or still rose) until the deadman's zero came
            top = int(np.flatnonzero(speeds >= speeds.max() - 0.002)[-1]) if after.any() else None
            figures = {"speed_at_loss_mps": round(speed, 3),
                       "braking_after_ms": round((int(twist.publish_ns[top]) - last_sent) / 1e6, 1)
                       if top is not None and speed > 0.01 else None,
                       "last_setpoint_value": [round(float(v), 3) for v in setpoints.values[-1]],
                       "still_after_ms": round((int(twist.publish_ns[still[0]]) - last_sent) / 1e6, 1)
                       if len(still) else None,
                       "platform_velocity_samples_after": int((commands.publish_ns > last_sent).sum())}
            results.append(figures)
            print("linkloss", figures, flush=True)
    return {"runs": results}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("what", choices=["transport", "loops", "linkloss", "security", "echo-zenoh", "ping-zenoh",
                                         "echo-udp",
                                         "ping-udp"])
    parser.add_argument("args", nargs="*")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--pin", action="store_true", help="loops: the loop on the last core, the bridges on the first")
    parser.add_argument("--low-latency", action="store_true", help="loops: the hosts on Zenoh's low-latency transport")
    parser.add_argument("--count", type=int, default=3000, help="round trips per transport run")
    parser.add_argument("--seconds", type=int, default=10,
                        help="length of each loops run; with linkloss, how long the operator drives before its death")
    options = parser.parse_args()
    a = options.args
    if options.what == "echo-zenoh":
        echo_zenoh(a[0], a[1], a[2:])
    elif options.what == "ping-zenoh":
        print(json.dumps(ping_zenoh(a[0], a[1], int(a[2]), a[3:])))
    elif options.what == "echo-udp":
        echo_udp(a[0])
    elif options.what == "ping-udp":
        print(json.dumps(ping_udp(a[0], int(a[1]))))
    else:
        out = ROOT / "bench" / "results" / "zenoh-link.json"
        out.parent.mkdir(exist_ok=True)
        saved = json.loads(out.read_text()) if out.exists() else {}
        if options.what == "transport":
            saved["transport"] = transport_runs(options.runs, options.count)
        elif options.what == "security":
            saved["security"] = security_runs(options.runs, options.count, options.seconds)
        elif options.what == "linkloss":
            saved["linkloss"] = linkloss_runs(options.runs, options.seconds)
        else:
            key = "loops" + ("_pinned" if options.pin else "") + ("_low_latency" if options.low_latency else "")
            saved[key] = loop_runs(options.runs, options.seconds, options.pin, options.low_latency)
        saved["machine"] = {"cpus": os.cpu_count(), "kernel": os.uname().release, "date": time.strftime("%Y-%m-%d")}
        out.write_text(json.dumps(saved, indent=1))
        print(f"wrote {out}")


if __name__ == "__main__":
    main()
