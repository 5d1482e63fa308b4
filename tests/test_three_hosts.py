"""Three hosts over mutual TLS: the access rules by certificate name hold for each pair, so a host that
reads one stream (an observer) can neither read nor drive another host's command (docs/security.md)."""

from __future__ import annotations

import os
import textwrap
import time
from pathlib import Path

import numpy as np

from hapticop.cli.hosts import keys_for
from hapticop.network import keys, wire
from hapticop.validation import validate_path
from tests.test_teleop_network import MARK, _free_port, log_says, start, stop, stranger, wait_for


def three_hosts(tmp_path: Path) -> tuple[Path, list[str]]:
    """a commands b ('command': a's noise read by b's recorder); b's telemetry is read by c, the observer."""
    ends = [f"127.0.0.1:{_free_port()}" for _ in range(3)]
    path = tmp_path / "three.yaml"
    path.write_text(textwrap.dedent(f"""\
        version: 1
        name: three{os.getpid()}
        security: {{keys: three.keys}}
        hosts:
          a: {{endpoints: [tls/{ends[0]}]}}
          b: {{endpoints: [tls/{ends[1]}]}}
          c: {{endpoints: [tls/{ends[2]}]}}
        threads:
          main_a: {{period: 1ms, deploy: main, host: a, schedules: {{0: [mediator, noise]}}}}
          main_b: {{period: 1ms, deploy: main, host: b, schedules: {{0: [mediator, probe, telemetry]}}}}
          main_c: {{period: 1ms, deploy: main, host: c, schedules: {{0: [mediator, watcher]}}}}
        activities:
          mediator: {{block: mediator}}
          noise: {{block: "tests.blocks:Noise"}}
          probe: {{block: "tests.blocks:Recorder"}}
          telemetry: {{block: "tests.blocks:Noise"}}
          watcher: {{block: "tests.blocks:Recorder"}}
        streams:
          command:
            from: noise.sample
            to: [probe.sample]
            network: {{priority: real_time, deadline: 100ms, stale: zero}}
          odometry:
            from: telemetry.sample
            to: [watcher.sample]
            network: {{priority: data, deadline: 100ms, stale: zero}}
        """))
    keys_for(path)
    return path, ends


def test_three_hosts_validate_and_each_bridge_allows_each_host_only_its_own_streams(tmp_path):
    path, _ = three_hosts(tmp_path)
    validated = validate_path(path)
    assert set(validated.hosts) == {"a", "b", "c"}
    for host in "abc":
        assert keys.problems(tmp_path / "three.keys", host) == []
    bridge = {h: validated.hosts[h].graph.loaded.activities["bridge"].params for h in "abc"}
    assert {w.stream: w.readers for w in bridge["a"].send} == {"command": ["b"]}
    assert {w.stream: w.host for w in bridge["b"].receive} == {"command": "a"}
    assert {w.stream: w.readers for w in bridge["b"].send} == {"odometry": ["c"]}


def test_an_observer_host_can_neither_read_nor_drive_the_command(tmp_path):
    """c, a host of the system with its own valid certificate, reads b's telemetry as the composition says.
    Holding c's key, a peer subscribes to everything at a and b, learns a's session from what it hears,
    and puts commands at b in a's session, far ahead in sequence, with a value a never writes. b's access
    rules drop them before its bridge (which refuses nothing from c), a's commands keep reaching b, and
    c's telemetry keeps flowing."""
    path, ends = three_hosts(tmp_path)
    system = f"three{os.getpid()}"
    hosts = {h: start(path, h, tmp_path / h) for h in "abc"}
    heard: list[tuple[str, bytes]] = []
    try:
        for h in "bc":
            wait_for(f"link up on {h}", lambda h=h: log_says(tmp_path / h / "bridge.log", "running"),
                     hosts.values())
        with stranger([f"tls/{e}" for e in ends[:2]], tmp_path / "three.keys", "c") as peer:
            for key in ("**", wire.sample_key(system, "command"), wire.state_key(system, "a")):  # `**` is denied whole
                peer.declare_subscriber(key, lambda s: heard.append((str(s.key_expr), s.payload.to_bytes())))
            since = time.monotonic_ns()
            value = np.full(3, MARK).tobytes()
            deadline = time.monotonic() + 3.0  # how long the observer tries; the checks below wait on events
            sent, own = 0, set()
            while time.monotonic() < deadline:
                sessions = {wire.SAMPLE.unpack_from(p)[0] for k, p in heard
                            if k.endswith("/stream/command") and p not in own}
                sessions |= {wire.STATE.unpack_from(p)[0] for k, p in heard if k.endswith("/state/a")}
                for session in sessions or {7}:
                    sent += 1
                    forged = wire.SAMPLE.pack(session, 10**6 + sent, time.clock_gettime_ns(time.CLOCK_REALTIME)) + value
                    own.add(forged)
                    peer.put(wire.sample_key(system, "command"), forged)
                time.sleep(0.01)
        assert all(p.poll() is None for p in hosts.values()), "the observer ended a host"
    finally:
        outs = {h: stop(p) for h, p in hosts.items()}
    command = np.load(tmp_path / "b" / "probe.npz")
    assert np.count_nonzero(command["stamps"] >= since) > 100, outs["b"]  # a's commands kept arriving
    assert not np.any(command["samples"] == MARK), "the observer's command reached host b's stream"
    assert "not from its owner's session" not in (tmp_path / "b" / "bridge.log").read_text(), \
        "the observer's puts reached b's bridge: b's access rules let c put the command"
    assert not any(k.endswith("/stream/command") and p not in own for k, p in heard), "the observer read a's command"
    telemetry = np.load(tmp_path / "c" / "watcher.npz")
    assert np.count_nonzero(telemetry["stamps"] >= since) > 100, outs["c"]  # what c may read, it reads
