"""Declared experiments (hapticop.experiment): the grid, the checks located in the file, failed runs,
resuming after a kill, refusing another experiment's table, Ray against the local pool, the report."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from hapticop.experiment.checks import load
from hapticop.experiment.description import Experiment
from hapticop.experiment.grid import cells, latin_hypercube, runs
from hapticop.experiment.study import run_study
from hapticop.experiment.table import TableMismatch, read

HERE = Path(__file__).parent / "experiments"
STUDY = HERE / "probe_study.yaml"
HAPTICOP = [sys.executable, "-m", "hapticop.cli"]


def write(tmp_path: Path, text: str, name: str = "study.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text.replace("COMPOSITION", str(HERE / "probe.yaml")))
    return path


def test_the_grid_crosses_factors_and_seeds_with_ids_that_do_not_move():
    experiment = Experiment.model_validate({
        "name": "g", "composition": "x.yaml", "seeds": {"count": 3},
        "factors": [{"path": "a.b", "values": [1, 2]},
                    {"path": "a.c", "range": {"start": 0.1, "stop": 0.3, "step": 0.1}}]})
    grid = cells(experiment)
    assert len(grid) == 6 and len({c.id for c in grid}) == 6
    assert sorted(c.values["a.c"] for c in grid) == [0.1, 0.1, 0.2, 0.2, 0.3, 0.3]
    every = runs(experiment)
    assert len(every) == 18 and len({r.id for r in every}) == 18
    # another order of the values gives the same run the same id
    swapped = experiment.model_copy(update={"factors": [experiment.factors[0].model_copy(update={"values": [2, 1]}),
                                                        experiment.factors[1]]})
    assert {r.id for r in runs(swapped)} == {r.id for r in every}


def test_a_latin_hypercube_is_the_same_every_time_and_fills_each_stratum_once():
    points = latin_hypercube(10, 7, {"x": (0.0, 1.0), "y": (10.0, 20.0)})
    assert points == latin_hypercube(10, 7, {"x": (0.0, 1.0), "y": (10.0, 20.0)})
    assert points != latin_hypercube(10, 8, {"x": (0.0, 1.0), "y": (10.0, 20.0)})
    assert sorted(int(p["x"] * 10) for p in points) == list(range(10))
    assert sorted(int(p["y"] - 10) for p in points) == list(range(10))


@pytest.mark.parametrize("factor, rule, line, field", [
    ("{path: activities.spring.params.stiffness, values: [1.0]}", "experiment-value", 5, "factors.0.values.0"),
    ("{path: activities.spring.params.kp_n_per_m, values: [100.0, 9000.0]}", "experiment-value", 5,
     "factors.0.values.1"),
    ("{path: activities.spring.params.kp_n_per_m, values: []}", "experiment-empty-grid", 5, "factors.0.values"),
    ("{path: activities.spring.params.kp_n_per_m, range: {start: 2, stop: 1, step: 1}}", "experiment-empty-grid", 5,
     "factors.0.range"),
    ("{path: activities.spring.params.kp_n_per_m, valuez: [1]}", "extra_forbidden", 5, "factors.0.valuez"),
])
def test_validate_refuses_a_bad_factor_with_file_line_and_field(tmp_path, factor, rule, line, field):
    path = write(tmp_path, f"version: 1\nname: bad\ncomposition: COMPOSITION\nfactors:\n  - {factor}\n")
    report = load(path).report
    assert not report.ok
    found = report.errors[0]
    assert (found.file, found.line, found.dotted_path) == (str(path), line, field), found.to_text()
    assert rule in found.rule or rule in found.message or rule == "extra_forbidden"
    cli = subprocess.run(HAPTICOP + ["validate", "--import-blocks", str(path)], capture_output=True, text=True,
                         timeout=120)
    assert cli.returncode == 1 and f"{path}:{line}:" in cli.stdout and "Traceback" not in cli.stdout + cli.stderr


KP = "{path: activities.spring.params.kp_n_per_m, name: kp, values: [100.0, 200.0]}"


@pytest.mark.parametrize("tail, line, field", [
    (f"factors:\n  - {KP}\nlatin_hypercube:\n  n: 3\n  bounds:\n    activities.spring.params.mode_x: [0, 1]\n",
     9, "latin_hypercube.bounds.activities.spring.params.mode_x"),
    (f"factors:\n  - {KP}\nlatin_hypercube:\n  n: 3\n  bounds:\n    activities.spring.params.kp_n_per_m: [1, 9000]\n",
     9, "latin_hypercube.bounds.activities.spring.params.kp_n_per_m"),
    (f"factors:\n  - {KP}\ncell_patches:\n  - where: {{kp: '200.0'}}\n"
     "    patch: {activities: {spring: {params: {mode: explode}}}}\n", 8, "cell_patches.0.patch"),
    (f"factors:\n  - {KP}\npaths: hallway\n", 6, "paths"),
    ("factors:\n  - {path: activities.nothing_here.params.kp, values: [1.0]}\n", 5, "factors.0.values.0"),
])
def test_validate_refuses_a_bad_bound_cell_patch_or_paths_with_file_line_and_field(tmp_path, tail, line, field):
    path = write(tmp_path, "version: 1\nname: bad\ncomposition: COMPOSITION\n" + tail)
    report = load(path).report
    assert not report.ok
    found = report.errors[0]
    assert (found.file, found.line, found.dotted_path) == (str(path), line, field), found.to_text()


def test_the_shipped_experiment_files_validate():
    for path in [STUDY, HERE / "tiny.yaml"]:
        assert load(path).report.ok, [d.to_text() for d in load(path).report.errors]


def test_a_run_that_crashes_and_one_that_hangs_are_failed_rows_and_the_others_finish(tmp_path):
    path = write(tmp_path, "version: 1\nname: crash\ncomposition: COMPOSITION\ntime_limit_s: 20\n"
                 "factors:\n  - {path: activities.spring.params.mode, values: [ok, raise, hang]}\n"
                 "  - {path: activities.spring.params.kp_n_per_m, values: [100.0, 200.0]}\n")
    done, failed = run_study(load(path), tmp_path / "out", workers=2)
    assert (done, failed) == (6, 4)
    rows = {(r["factor.mode"], r["factor.kp_n_per_m"]): r for r in read(tmp_path / "out").to_pylist()}
    for kp in ("100.0", "200.0"):
        assert rows[("ok", kp)]["status"] == "done" and rows[("ok", kp)]["metric.force_peak_n"] > 0
        assert rows[("raise", kp)]["status"] == "failed" and "spring" in rows[("raise", kp)]["message"]
        assert rows[("hang", kp)]["status"] == "failed" and "time limit" in rows[("hang", kp)]["message"]
        assert all(rows[(m, kp)]["composition_hash"] for m in ("ok", "raise", "hang"))


def _parts(out: Path) -> int:
    return len(list((out / "parts").glob("*.parquet"))) if (out / "parts").exists() else 0


def _parent(pid: int) -> int:
    try:
        return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])
    except (OSError, IndexError, ValueError):
        return 0


def _runners(ancestor: int) -> list[int]:
    """The experiment runs (`python -m hapticop.experiment.runner`) started by `ancestor` or its descendants."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            if b"hapticop.experiment.runner" not in (entry / "cmdline").read_bytes():
                continue
        except OSError:
            continue
        pid = up = int(entry.name)
        while up > 1:
            up = _parent(up)
            if up == ancestor:
                found.append(pid)
                break
    return found


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


def _wait_gone(pids: list[int], bound_s: float = 60.0) -> list[int]:
    deadline = time.monotonic() + bound_s
    while any(_alive(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.1)
    return [p for p in pids if _alive(p)]


def test_a_study_killed_halfway_resumes_without_repeating_a_run_and_leaves_no_run_behind(tmp_path):
    out = tmp_path / "out"
    command = HAPTICOP + ["experiment", "run", str(STUDY), "--workers", "1", "--out", str(out)]
    child = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 300
        while not (_parts(out) >= 2 and _runners(child.pid)) and time.monotonic() < deadline \
                and child.poll() is None:
            time.sleep(0.05)
        in_flight = _runners(child.pid)
    finally:
        os.killpg(child.pid, signal.SIGKILL)  # the study, as a crash would (its runs are in groups of their own)
        child.wait()
    assert in_flight, "no run was in flight at the kill"
    assert not _wait_gone(in_flight), "a run outlived the study that started it"
    first = read(out).column("run_id").to_pylist()
    assert 2 <= len(first) < 6, "the kill came too late to test a resume"
    again = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr
    ids = read(out).column("run_id").to_pylist()
    assert len(ids) == len(set(ids)) == 6, "a run was repeated or lost"
    assert f"{len(first)} from before" in again.stderr
    assert set(first) <= set(ids)


HANGING = ("version: 1\nname: stop\ncomposition: COMPOSITION\ntime_limit_s: LIMIT\n"
           "factors:\n  - {path: activities.spring.params.mode, values: [ok, hang]}\n"
           "  - {path: activities.spring.params.kp_n_per_m, values: [100.0, 200.0]}\n")


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM, signal.SIGKILL], ids=["ctrl-c", "term", "crash"])
def test_ctrl_c_stops_the_study_and_its_runs_at_once_and_the_same_command_resumes(tmp_path, signum):
    """Two runs finish, the third hangs (for the 600 s of its time limit): Ctrl+C (or `kill`) stops the
    study and kills that run now, records nothing for it, and says how to resume; killed outright (a crash),
    the study cannot stop its run, which stops itself once its study is gone."""
    path = write(tmp_path, HANGING.replace("LIMIT", "600"))
    out = tmp_path / "out"
    command = HAPTICOP + ["experiment", "run", str(path), "--workers", "1", "--out", str(out)]
    child = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             start_new_session=True)
    try:
        deadline = time.monotonic() + 300
        while not (_parts(out) >= 2 and _runners(child.pid)) and time.monotonic() < deadline \
                and child.poll() is None:
            time.sleep(0.05)
        in_flight = _runners(child.pid)
        assert _parts(out) == 2 and in_flight, "the hanging run was not reached"
        child.send_signal(signum)
        _, err = child.communicate(timeout=120)  # the hanging run has 600 s left: only stopping it ends this
    finally:
        if child.poll() is None:
            os.killpg(child.pid, signal.SIGKILL)
            child.wait()
    if signum == signal.SIGKILL:
        assert child.returncode == -signal.SIGKILL
    else:
        assert child.returncode == 130 and "interrupted" in err and "Traceback" not in err, err
    assert not _wait_gone(in_flight), "the run in flight outlived its study"
    assert _parts(out) == 2 and set(read(out).column("status").to_pylist()) == {"done"}
    path.write_text(HANGING.replace("LIMIT", "3").replace("COMPOSITION", str(HERE / "probe.yaml")))  # the hangs fail
    again = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0 and "2 from before" in again.stderr, again.stderr
    rows = read(out).to_pylist()
    assert len(rows) == len({r["run_id"] for r in rows}) == 4
    assert sorted(r["status"] for r in rows) == ["done", "done", "failed", "failed"]


def test_failed_runs_are_kept_on_resume_and_run_again_with_retry_failed(tmp_path):
    """A failure is a result: resuming keeps it. `--retry-failed` runs the failed runs again (here they failed
    for a time limit too short, which is not part of what the experiment means); each run keeps one row."""
    text = ("version: 1\nname: retry\ncomposition: COMPOSITION\ntime_limit_s: LIMIT\n"
            "factors:\n  - {path: activities.spring.params.kp_n_per_m, values: [100.0, 200.0]}\n")
    path = write(tmp_path, text.replace("LIMIT", "0.01"))
    out = tmp_path / "out"
    assert run_study(load(path), out) == (2, 2)
    assert {r["message"].split(":")[0] for r in read(out).to_pylist()} == {"time limit"}
    path.write_text(text.replace("LIMIT", "120").replace("COMPOSITION", str(HERE / "probe.yaml")))
    assert run_study(load(path), out) == (0, 0)  # kept as they were
    assert set(read(out).column("status").to_pylist()) == {"failed"}
    cli = subprocess.run(HAPTICOP + ["experiment", "run", str(path), "--out", str(out), "--retry-failed"],
                         capture_output=True, text=True, timeout=600)
    assert cli.returncode == 0 and "2 runs now, 0 failed" in cli.stdout, cli.stderr
    rows = read(out).to_pylist()
    assert len(rows) == 2 and {r["status"] for r in rows} == {"done"} and _parts(out) == 4
    assert all(r["metric.force_peak_n"] > 0 for r in rows)
    assert run_study(load(path), out, retry_failed=True) == (0, 0)  # nothing failed is left to retry


def test_a_table_of_another_experiment_or_version_is_refused(tmp_path):
    out = tmp_path / "out"
    small = write(tmp_path, "version: 1\nname: one\ncomposition: COMPOSITION\n"
                  "factors:\n  - {path: activities.spring.params.kp_n_per_m, values: [100.0]}\n", "one.yaml")
    assert run_study(load(small), out) == (1, 0)
    other = write(tmp_path, "version: 1\nname: one\ncomposition: COMPOSITION\n"
                  "factors:\n  - {path: activities.spring.params.kp_n_per_m, values: [150.0]}\n", "two.yaml")
    with pytest.raises(TableMismatch, match="another experiment"):
        run_study(load(other), out)
    cli = subprocess.run(HAPTICOP + ["experiment", "run", str(other), "--out", str(out)], capture_output=True,
                         text=True, timeout=120)
    assert cli.returncode == 1 and "another experiment" in cli.stderr and "Traceback" not in cli.stderr
    manifest = json.loads((out / "manifest.json").read_text())
    (out / "manifest.json").write_text(json.dumps({**manifest, "software_version": "0.0.1"}))
    with pytest.raises(TableMismatch, match="hapticop 0.0.1"):
        run_study(load(small), out)
    assert read(out).num_rows == 1


def test_the_report_judges_each_cell_against_the_targets_and_draws_them(tmp_path):
    out = tmp_path / "out"
    run_study(load(STUDY), out)
    cli = subprocess.run(HAPTICOP + ["experiment", "report", str(STUDY), "--out", str(out)], capture_output=True,
                         text=True, timeout=120)
    assert cli.returncode == 0, cli.stderr
    page = (out / "report" / "report.md").read_text()
    assert "force_peak_n <= 5 (every run)" in page and "force_peak_n <= 5 (mean)" in page
    assert page.count("| 2 | 0 |") == 3 and "95 % CI" in page
    picture = out / "report" / "plots" / "force_peak_n.png"
    assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and "plots/force_peak_n.png" in page


@pytest.fixture(scope="module")
def local_ray():
    """A Ray cluster of two CPUs on this machine, started as the tests' driver."""
    try:
        import ray
    except ImportError:
        if os.environ.get("CI"):
            pytest.fail("ray is missing under CI: install hapticop[cluster]")
        pytest.skip("ray is not installed (hapticop[cluster])")
    short = tempfile.mkdtemp(prefix="ray", dir="/tmp")  # Ray's socket paths must stay under 108 bytes
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, _temp_dir=short)
    try:
        yield ray
    finally:
        ray.shutdown()
        shutil.rmtree(short, ignore_errors=True)


def test_the_same_study_on_a_local_ray_cluster_gives_the_same_metrics_bit_for_bit(tmp_path, local_ray):
    loaded = load(STUDY)
    run_study(loaded, tmp_path / "pool", workers=2)
    run_study(loaded, tmp_path / "ray-out", ray="auto")

    def metrics(folder: str) -> dict:
        kept = ("status", "composition_hash", "tries")
        return {r["run_id"]: {k: v for k, v in r.items() if k.startswith("metric.") or k in kept}
                for r in read(tmp_path / folder).to_pylist()}

    pool, cluster = metrics("pool"), metrics("ray-out")
    assert len(pool) == 6 and pool == cluster


def _kill_the_first_ray_worker_running_a_run(killed: list) -> None:
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline:
        for runner in _runners(os.getpid()):
            worker = _parent(runner)
            try:
                is_worker = Path(f"/proc/{worker}/cmdline").read_bytes().startswith(b"ray::")
            except OSError:
                continue
            if is_worker:
                os.kill(worker, signal.SIGKILL)
                killed.append(runner)
                return
        time.sleep(0.05)


@pytest.mark.parametrize("retries", [1, 0])
def test_a_run_lost_with_its_ray_worker_is_tried_again_and_reported(tmp_path, local_ray, capsys, retries):
    """The worker running the run is killed (as a node lost): the run is submitted again and its row says
    it took two tries and what was lost; with no retries left it is a failed row, and the study goes on."""
    import threading

    path = write(tmp_path, f"version: 1\nname: lost\ncomposition: COMPOSITION\nretries: {retries}\n"
                 "factors:\n  - {path: activities.spring.params.kp_n_per_m, values: [100.0]}\n")
    killed: list[int] = []
    killer = threading.Thread(target=_kill_the_first_ray_worker_running_a_run, args=(killed,))
    killer.start()
    try:
        done, failed = run_study(load(path), tmp_path / "out", ray="auto")
    finally:
        killer.join()
    assert killed, "no run was seen on a Ray worker"
    assert not _wait_gone(killed), "the run outlived its lost worker"
    [row] = read(tmp_path / "out").to_pylist()
    said = capsys.readouterr().err
    if retries:
        assert (done, failed) == (1, 0) and row["status"] == "done" and row["tries"] == 2
        assert row["metric.force_peak_n"] > 0 and "lost before: " in row["message"]
        assert "lost on the cluster" in said and "trying again (2 of 2)" in said
    else:
        assert (done, failed) == (1, 1) and row["status"] == "failed" and row["tries"] == 1
        assert row["message"].startswith("lost on the cluster 1 times: ")
        assert "recorded as failed" in said


def test_a_marker_quoted_inside_a_line_is_text_not_a_region():
    """The CLI reference quotes the marker in a table cell; only a marker that starts its line opens a region."""
    from hapticop.experiment.regions import regions

    text = ("| `--docs` | between their `<!-- experiment NAME SUMMARY -->` markers |\n"
            "<!-- experiment hallway hallway_readme: generated -->\n| a | b |\n<!-- end experiment -->\n")
    assert regions(text) == [("hallway", "hallway_readme", "| a | b |\n")]
