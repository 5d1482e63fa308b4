"""The control socket's default directory is made like a run directory (the user's alone; another
user's directory or a planted link refused in one line, exit 2, before anything is made), and
a user may let their group read their runs."""

from __future__ import annotations

import os
import stat
import subprocess
import sys

import pytest

from hapticop.rundirs import private_directory

from .conftest import ROOT
from .runtime_helpers import COUNTER


def _compose(tmp_path, *options: str, env: dict | None = None, clock: str = "realtime"):
    path = tmp_path / "c.yaml"
    path.write_text(COUNTER)
    return subprocess.run([sys.executable, "-m", "hapticop.cli", "compose", str(path), "--clock", clock,
                           "--duration", "50ms", *options], cwd=ROOT, capture_output=True, text=True, timeout=120,
                          env={**os.environ, **(env or {})})


def _mode(path) -> int:
    return stat.S_IMODE(os.lstat(path).st_mode)


def test_a_link_planted_where_the_control_socket_goes_stops_the_run_before_it_starts(tmp_path):
    runtime_dir, elsewhere = tmp_path / "xdg", tmp_path / "elsewhere"
    runtime_dir.mkdir()
    elsewhere.mkdir()
    (runtime_dir / "hapticop").symlink_to(elsewhere)
    done = _compose(tmp_path, "--run-dir", str(tmp_path / "run"), env={"XDG_RUNTIME_DIR": str(runtime_dir)})
    assert done.returncode == 2, done.stderr
    assert done.stderr.splitlines() == [
        f"hapticop: {runtime_dir / 'hapticop'} is not a directory (a link or a file is there): not writing into it"]
    assert not (tmp_path / "run").exists() and not list(elsewhere.iterdir())


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root to make a directory that belongs to another user")
def test_another_users_control_directory_is_refused(tmp_path):
    runtime_dir = tmp_path / "xdg"
    (runtime_dir / "hapticop").mkdir(parents=True)
    os.chown(runtime_dir / "hapticop", 65534, 65534)
    done = _compose(tmp_path, "--run-dir", str(tmp_path / "run"), env={"XDG_RUNTIME_DIR": str(runtime_dir)})
    assert done.returncode == 2, done.stderr
    assert done.stderr.splitlines() == [
        f"hapticop: {runtime_dir / 'hapticop'} belongs to user 65534, not to you: not writing into it "
        "(remove it, or give --control PATH)"]
    assert not (tmp_path / "run").exists()


def test_the_default_control_directory_is_made_private(tmp_path):
    runtime_dir = tmp_path / "xdg"
    runtime_dir.mkdir()
    done = _compose(tmp_path, "--run-dir", str(tmp_path / "run"), env={"XDG_RUNTIME_DIR": str(runtime_dir)})
    assert done.returncode == 0, done.stderr
    assert _mode(runtime_dir / "hapticop") == 0o700 and os.lstat(runtime_dir / "hapticop").st_uid == os.geteuid()
    assert f"control socket {runtime_dir / 'hapticop' / 'c.sock'}" in (tmp_path / "run" / "system.log").read_text()
    assert not (runtime_dir / "hapticop" / "c.sock").exists()  # gone with the run


def test_a_group_readable_run_lets_the_group_read_and_no_one_else(tmp_path):
    done = _compose(tmp_path, "--run-dir", str(tmp_path / "run"), clock="virtual",
                    env={"HAPTICOP_GROUP_READABLE": "1"})
    assert done.returncode == 0, done.stderr
    files = [p for p in (tmp_path / "run").rglob("*") if p.is_file()]
    assert files and all(_mode(p) == 0o640 for p in files), {p.name: oct(_mode(p)) for p in files}
    assert _mode(tmp_path / "run") == 0o750


def test_a_directory_is_set_to_the_mode_asked_either_way(tmp_path):
    assert _mode(private_directory(tmp_path / "runs", 0o750)) == 0o750
    assert _mode(private_directory(tmp_path / "runs")) == 0o700  # a later private run closes it again
