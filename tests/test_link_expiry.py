"""A host's certificate that ends during a run: its bridge closes the link at that moment (Zenoh's own
`close_link_on_expiration` panics, docs/security.md), the other host hears nothing more and its deadman
turns the command invalid, and neither process crashes. `validate` and `hosts keys` warn beforehand."""

from __future__ import annotations

import datetime as dt
import time

import numpy as np

from hapticop.cli.hosts import keys_for
from hapticop.network import keys
from hapticop.validation import validate_path
from tests.test_teleop_network import _free_port, log_says, start, stop, two_hosts, wait_for

LIFE_S = 30.0  # the short certificate's life: long enough for two hosts to start on a loaded machine


def test_a_certificate_that_ends_mid_run_stops_the_command_by_the_deadman(tmp_path):
    path = two_hosts(tmp_path, f"tcp/127.0.0.1:{_free_port()}", f"tcp/127.0.0.1:{_free_port()}", name="ending")
    directory = tmp_path / "ending.keys"
    keys.make_host(directory, "a", ["127.0.0.1"], days=LIFE_S / 86400, force=True)  # a, the writer: the operator
    ends = keys.expiry(directory / "a.pem")
    b = start(path, "b", tmp_path / "b")
    a = start(path, "a", tmp_path / "a")
    try:
        wait_for("link up on b", lambda: log_says(tmp_path / "b" / "bridge.log", "running"), [a, b])
        assert dt.datetime.now(dt.UTC) < ends, "the hosts took longer to start than the certificate lives"
        wait_for("a's link closed at its certificate's end",
                 lambda: log_says(tmp_path / "a" / "bridge.log", "certificate has expired"), [a, b])
        wait_for("link lost on b", lambda: log_says(tmp_path / "b" / "bridge.log", "link lost"), [a, b])
        time.sleep(0.5)
        assert a.poll() is None and b.poll() is None, "a host ended at the certificate's end"
    finally:
        out_a = stop(a)
        out_b = stop(b)
    assert "panic" not in out_a + out_b and "Traceback" not in out_a + out_b, out_a + out_b
    data = np.load(tmp_path / "b" / "probe.npz")
    now, valid = data["cycles"][:, 0], data["cycles"][:, 1].astype(bool)
    assert valid.any(), out_b  # the command was followed while the certificate lived
    last = np.flatnonzero(valid)[-1]
    assert last < len(valid) - 1 and not valid[last + 1:].any(), "the command stayed valid after the link closed"
    # it ended at the deadman's deadline after the last sample, not held
    assert now[-1] - now[last] > 100_000_000, out_b


def test_validate_and_hosts_keys_warn_of_a_certificate_ending_soon(tmp_path):
    path = two_hosts(tmp_path, "tcp/127.0.0.1:7447", "tcp/127.0.0.1:7448", name="soon")
    keys.make_host(tmp_path / "soon.keys", "b", ["127.0.0.1"], days=3, force=True)
    warnings = [d for d in validate_path(path).report.diagnostics if d.rule == "security-expiry"]
    assert len(warnings) == 1 and "host 'b'" in warnings[0].message and "b.pem" in warnings[0].message, warnings
    assert any(line.startswith("warning:") and "b.pem" in line for line in keys_for(path))
