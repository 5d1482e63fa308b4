"""A composition whose devices are not there stops before anything is made, with one message
naming each missing device (systems/hardware.yaml on a machine without the robot)."""

from __future__ import annotations

import socket
import subprocess
import sys
import threading

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Params
from hapticop.runtime.preflight import missing_devices
from hapticop.validation import validate_path

from .conftest import ROOT, SYSTEMS


def _free_port() -> int:
    """A loopback port nobody listens on (bound, then let go)."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def test_the_real_robot_composition_names_every_missing_device_and_leaves_nothing(tmp_path):
    port = _free_port()
    here = tmp_path / "hardware_here.yaml"  # the real-robot file, pointed at what this test controls
    here.write_text(f"""
extends: {SYSTEMS / 'hardware.yaml'}
activities:
  falcon: {{params: {{firmware: {tmp_path / 'nvent_firmware.bin'}}}}}
  lidar: {{params: {{host: 127.0.0.1, port: {port}}}}}
  ethercat: {{params: {{interface: hapticop-none9}}}}
""")
    run_dir = tmp_path / "run"
    done = subprocess.run([sys.executable, "-m", "hapticop.cli", "compose", str(here), "--duration", "2s",
                           "--run-dir", str(run_dir), "--control", str(tmp_path / "control.sock")],
                          cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 69, done.stderr
    lines = done.stderr.splitlines()
    assert lines[0] == "hapticop: hallway_hardware not started: 3 of its devices are not there", done.stderr
    missing = dict(line.strip().split(": ", 1) for line in lines[1:])
    assert set(missing) == {"falcon", "lidar", "ethercat"}, done.stderr
    assert f"{tmp_path / 'nvent_firmware.bin'} does not exist" in missing["falcon"]
    assert "Falcon on USB" in missing["falcon"]  # none there, or no way to look
    assert missing["lidar"].startswith(f"no LIDAR answering: 127.0.0.1:{port} refused the connection")
    assert missing["ethercat"] == "no network interface named 'hapticop-none9' for the EtherCAT segment (see `ip link`)"
    assert "Traceback" not in done.stderr
    assert not run_dir.exists() and not (tmp_path / "control.sock").exists()  # nothing was made: no region,
    # no processes (they are started after the run directory), no socket


class WaitingParams(Params):
    answer: str = ""


RELEASE = threading.Event()


class Waiting(Block):
    """A device check that never comes back until the test lets it."""

    Params = WaitingParams

    @classmethod
    def preflight(cls, params: WaitingParams, timeout_s: float) -> str | None:
        if params.answer:
            return params.answer
        RELEASE.wait()
        return None


def test_checks_run_together_and_one_that_hangs_is_named_at_the_bound(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("""
version: 1
threads:
  main: {period: 1ms, deploy: main, schedules: {0: [mediator, hangs, absent, fine]}}
activities:
  mediator: {block: mediator}
  hangs: {block: "tests.test_preflight:Waiting"}
  absent: {block: "tests.test_preflight:Waiting", params: {answer: "no widget on the bus"}}
  fine: {block: "tests.blocks:Stuck"}
""")
    validated = validate_path(path)
    assert validated.report.ok
    try:
        missing = missing_devices(validated.graph.loaded, timeout_s=0.05)
    finally:
        RELEASE.set()
    assert missing == {"hangs": "no answer within 0.05 s", "absent": "no widget on the bus"}


def test_a_scanner_that_answers_is_not_missing():
    """The check speaks to the scanner as `hapticop devices` does (the project's simulator here)."""
    from hapticop.blocks.lidar import Lidar
    from hapticop.devices.sick.simulator import TiMSimulator

    with TiMSimulator() as sim:
        sim.start()
        params = Lidar.Params(driver="tcp", host=sim.host, port=sim.port)
        assert Lidar.preflight(params, timeout_s=5.0) is None
