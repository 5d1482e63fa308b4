"""Run directories: per user and private, never another user's or a planted link, and not
without bound; what a run writes is its owner's alone."""

from __future__ import annotations

import os
import stat

import pytest

from hapticop.rundirs import RunDirectoryError, new_run_directory, private_directory, prune_runs

from .runtime_helpers import COUNTER


def _mode(path) -> int:
    return stat.S_IMODE(os.lstat(path).st_mode)


def test_a_private_directory_is_made_for_its_owner_alone(tmp_path):
    made = private_directory(tmp_path / "runs")
    assert _mode(made) == 0o700 and os.lstat(made).st_uid == os.geteuid()
    (tmp_path / "open").mkdir(mode=0o777)
    os.chmod(tmp_path / "open", 0o777)
    assert _mode(private_directory(tmp_path / "open")) == 0o700  # ours, but open: closed


def test_a_planted_link_or_file_is_refused_not_followed(tmp_path):
    target = tmp_path / "elsewhere"
    target.mkdir()
    (tmp_path / "link").symlink_to(target)
    with pytest.raises(RunDirectoryError, match="is not a directory"):
        private_directory(tmp_path / "link")
    (tmp_path / "file").write_text("x")
    with pytest.raises(RunDirectoryError, match="is not a directory"):
        private_directory(tmp_path / "file")


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root to make a directory that belongs to another user")
def test_another_users_directory_is_refused(tmp_path):
    theirs = tmp_path / "theirs"
    theirs.mkdir()
    os.chown(theirs, 65534, 65534)
    with pytest.raises(RunDirectoryError, match="belongs to user 65534, not to you"):
        private_directory(theirs)


def test_only_the_newest_runs_are_kept(tmp_path):
    runs = []
    for i in range(5):
        run = tmp_path / f"hallway-20261124-2300{i:02d}-{100 + i}"
        run.mkdir()
        os.utime(run, ns=(i * 10**9, i * 10**9))
        runs.append(run)
    (tmp_path / "not-a-run").mkdir()
    (tmp_path / "hallway-20261124-230099-1").symlink_to(tmp_path / "not-a-run")  # a link is never a run
    removed = prune_runs(tmp_path, keep=2)
    assert removed == runs[:3]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        [runs[3].name, runs[4].name, "not-a-run", "hallway-20261124-230099-1"])


def test_the_default_run_directory_is_this_users_and_private(monkeypatch):
    monkeypatch.setenv("HAPTICOP_KEEP_RUNS", "50")
    run = new_run_directory("probe")
    try:
        assert run.parent.name == f"hapticop-{os.geteuid()}"
        assert _mode(run) == 0o700 and _mode(run.parent) == 0o700
    finally:
        run.rmdir()


def test_what_a_run_writes_is_its_owners_alone(tmp_path):
    """`hapticop compose` writes with umask 077, whatever the shell's: logs, results, timing."""
    import subprocess
    import sys

    from .conftest import ROOT

    path = tmp_path / "c.yaml"
    path.write_text(COUNTER)
    done = subprocess.run([sys.executable, "-m", "hapticop.cli", "compose", str(path), "--clock", "virtual",
                           "--duration", "50ms", "--run-dir", str(tmp_path / "run")], cwd=ROOT, capture_output=True,
                          text=True, timeout=120, preexec_fn=lambda: os.umask(0o022))
    assert done.returncode == 0, done.stderr
    files = [p for p in (tmp_path / "run").rglob("*") if p.is_file()]
    assert files and all(_mode(p) & 0o077 == 0 for p in files), {p.name: oct(_mode(p)) for p in files}
