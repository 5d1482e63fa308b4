"""The link's keys (docs/security.md): made by `hapticop hosts keys`, owner-only, never replaced
unless asked; and `validate` and the bridge's pre-flight check place what is wrong with them
(missing, expired, another host's, readable by others)."""

from __future__ import annotations

import datetime as dt
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from hapticop.blocks.bridge import BridgeParams, ZenohBridge
from hapticop.network import keys
from hapticop.validation import validate_path

ROOT = Path(__file__).resolve().parent.parent


def two_hosts(tmp_path: Path) -> Path:
    path = tmp_path / "pair.yaml"
    path.write_text(textwrap.dedent("""\
        version: 1
        name: pair
        security: {keys: pair.keys}
        hosts:
          desk: {endpoints: [tls/127.0.0.1:7461]}
          robot: {endpoints: [tls/10.9.8.7:7462]}
        threads:
          main: {period: 1ms, deploy: main, host: desk, schedules: {0: [mediator, counter]}}
          robot_main: {period: 1ms, deploy: main, host: robot, schedules: {0: [mediator, echo]}}
        activities:
          mediator: {block: mediator}
          counter: {block: counter}
          echo: {block: echo}
        streams:
          count:
            from: counter.count
            to: [echo.input]
            network: {priority: real_time, deadline: 50ms, stale: zero}
        """))
    return path


def hapticop(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hapticop.cli", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=120)


def errors(path: Path) -> list[tuple[str, int, str]]:
    report = validate_path(path).report
    return [(d.rule, d.line, d.message) for d in report.errors]


def test_hosts_keys_makes_a_ca_and_each_hosts_private_files_and_keeps_them(tmp_path):
    path = two_hosts(tmp_path)
    assert errors(path) and all(rule == "security-keys" for rule, _, _ in errors(path))  # none made yet
    done = hapticop("hosts", "keys", str(path))
    assert done.returncode == 0, done.stderr
    directory = tmp_path / "pair.keys"
    assert sorted(p.name for p in directory.iterdir()) == ["ca.key", "ca.pem", "desk.key", "desk.pem",
                                                            "robot.key", "robot.pem"]
    assert all(p.stat().st_mode & 0o777 == 0o600 for p in directory.iterdir())
    assert directory.stat().st_mode & 0o077 == 0
    assert errors(path) == []
    before = {p.name: p.read_bytes() for p in directory.iterdir()}
    again = hapticop("hosts", "keys", str(path))  # nothing replaced without --force
    assert again.returncode == 0 and "kept" in again.stdout
    assert {p.name: p.read_bytes() for p in directory.iterdir()} == before
    # rotation: new host keys under the same CA; then a new CA too
    assert hapticop("hosts", "keys", str(path), "--force").returncode == 0
    after = {p.name: p.read_bytes() for p in directory.iterdir()}
    assert after["ca.pem"] == before["ca.pem"] and after["desk.key"] != before["desk.key"]
    assert hapticop("hosts", "keys", str(path), "--new-ca").returncode == 2  # only with --force
    assert hapticop("hosts", "keys", str(path), "--force", "--new-ca").returncode == 0
    assert (directory / "ca.pem").read_bytes() != before["ca.pem"]
    assert errors(path) == []


def test_the_certificate_names_the_host_and_where_it_is_reached(tmp_path):
    path = two_hosts(tmp_path)
    assert hapticop("hosts", "keys", str(path)).returncode == 0
    from cryptography import x509

    cert = x509.load_pem_x509_certificate((tmp_path / "pair.keys" / "robot.pem").read_bytes())
    assert cert.subject.rfc4514_string() == "CN=robot"
    san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert "10.9.8.7" in {str(a) for a in san.get_values_for_type(x509.IPAddress)}
    assert "robot" in san.get_values_for_type(x509.DNSName)


@pytest.mark.parametrize("defect", ["missing", "expired", "another host's", "readable", "foreign CA",
                                    "moved address"])
def test_validate_and_preflight_place_what_is_wrong_with_a_hosts_keys(tmp_path, defect):
    path = two_hosts(tmp_path)
    assert hapticop("hosts", "keys", str(path)).returncode == 0
    directory = tmp_path / "pair.keys"
    expected = {"missing": "desk.pem is missing", "expired": "desk.pem expired on",
                "another host's": "is host 'robot''s certificate, not host 'desk''s",
                "readable": "desk.key is readable by others (mode 644)",
                "foreign CA": "desk.pem is not signed by ca.pem",
                "moved address": "does not name 10.1.1.1"}[defect]
    if defect == "missing":
        (directory / "desk.pem").unlink()
    elif defect == "expired":
        keys.make_host(directory, "desk", ["127.0.0.1"], days=365, force=True,
                       start=dt.datetime.now(dt.UTC) - dt.timedelta(days=400))
    elif defect == "another host's":
        shutil.copy(directory / "robot.pem", directory / "desk.pem")
        shutil.copy(directory / "robot.key", directory / "desk.key")
    elif defect == "readable":
        (directory / "desk.key").chmod(0o644)
    elif defect == "foreign CA":
        other = tmp_path / "other"
        other.mkdir()
        keys.make_ca(other, "other")
        keys.make_host(other, "desk", ["127.0.0.1"])
        for name in ("desk.pem", "desk.key"):
            shutil.copy(other / name, directory / name)
    elif defect == "moved address":
        path.write_text(path.read_text().replace("tls/127.0.0.1:7461", "tls/10.1.1.1:7461"))
    found = errors(path)
    assert len(found) == 1, found
    rule, line, message = found[0]
    assert rule == "security-keys" and line == 3 and expected in message and "host 'desk'" in message, found
    # the bridge's pre-flight check at start says the same of its own host
    tls = {k: str(v) for k, v in vars(keys.files(directory, "desk")).items()}
    params = BridgeParams(host="desk", listen=["tls/10.1.1.1:7461" if defect == "moved address" else
                                               "tls/127.0.0.1:7461"], tls=tls)
    said = ZenohBridge.preflight(params, 1.0)
    if defect == "moved address":
        assert said is None  # a host checks its own files; the other hosts check the address they dial
    else:
        assert said is not None and expected in said, said


def test_a_deployed_host_needs_only_its_own_private_key(tmp_path):
    """On the robot's machine, the directory holds the CA's certificate, every host's certificate and the
    robot's private key: validate accepts it; a directory with no private key at all is refused."""
    path = two_hosts(tmp_path)
    assert hapticop("hosts", "keys", str(path)).returncode == 0
    directory = tmp_path / "pair.keys"
    (directory / "desk.key").unlink()
    (directory / "ca.key").unlink()
    assert errors(path) == []
    (directory / "robot.key").unlink()
    found = errors(path)
    assert [m for _, _, m in found] == [f"host 'desk': {directory / 'desk.key'} is missing",
                                        f"host 'robot': {directory / 'robot.key'} is missing"], found


def test_key_files_are_written_whole_and_never_over_an_existing_one(tmp_path):
    keys.make_ca(tmp_path, "t")
    before = (tmp_path / "ca.pem").read_bytes()
    with pytest.raises(FileExistsError):
        keys.make_ca(tmp_path, "t")
    assert (tmp_path / "ca.pem").read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ca.key", "ca.pem"]  # no temporary left behind
