"""Replaying a recording (`hapticop replay|report`): an activity run again on its recorded inputs, its outputs judged.

Each chosen activity is replayed by a composition of its own, rewritten from the recording
(`observe.rewrite`: the activity behind a `recorded_source`, its thread paced at the recorded
cycles), validated and run by `System` under the virtual clock, with its outputs recorded; the
replayed outputs are then compared with the recorded ones, sample by sample (`recording.compare`).
Nothing tells the block it is replayed: it is built, configured, stepped, retuned and cleaned by
the runtime that ran it.

Cycles a wall-clock run missed were never stepped, so they are not replayed either; samples
another thread published while the activity computed are not seen before the cycle that saw
them. Under the virtual clock and on the wall clock alike the outputs come back equal to the bit
(docs/recording.md, "Replay").
"""

from __future__ import annotations

import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

from hapticop.blocks.registry import blocks_of_a_recording
from hapticop.composition.diagnostics import Severity
from hapticop.composition.documents import dump
from hapticop.composition.yamlsource import parse_text
from hapticop.observe.replay_run import ReplayError, Run, choose, open_run, why_not
from hapticop.observe.rewrite import RecordedCycles, Rewrite, rewrite
from hapticop.recording.compare import Compared, compare
from hapticop.recording.reading import RecordingError, series_of
from hapticop.runtime.assembly import thread_of
from hapticop.runtime.system import RunOptions, run_system
from hapticop.validation import Validated, validate_source

__all__ = ["ReplayError", "Replayed", "leaving_results", "open_run", "replay", "results", "validated_rewrite"]


@dataclass
class Replayed:
    """One activity's replay."""

    activity: str
    block: str
    thread: str
    cycles: int  # replayed: every recorded step of the activity, configuring and cleaning too
    start_s: float
    end_s: float
    inputs: list[str]
    compared: list[Compared]
    diverged: str = ""  # where the replayed life cycle left the recorded one, in words
    computed: int = 0  # cycles that ran the block's compute

    @property
    def ok(self) -> bool:
        return not self.diverged and all(c.ok for c in self.compared)


def validated_rewrite(run: Run, activity: str) -> tuple[Rewrite, Validated]:
    """The rewritten composition, checked as `hapticop validate` checks a file."""
    rewritten = rewrite(run, activity)
    source = parse_text(dump(rewritten.tree), f"{run.path}:replay-{activity}.yaml")
    with blocks_of_a_recording(run.trusted, run.path.parent):  # as `open_run` resolved them
        validated = validate_source(source, scripted=False)
    # No flag map writes the flags the replayed activity reads: the pacing puts back, each cycle, the
    # values the recorded cycle started from, so a wait for one ends when it ended in the run. An
    # activity beside it is configured and never started: it waits for nothing.
    waits = tuple(f"activity '{name}' waits for flag '{name}." for name in (activity, *rewritten.beside))
    never = tuple(f"'{name}' starts on request" for name in rewritten.beside)
    errors = [d for d in validated.report.diagnostics if d.severity is Severity.ERROR
              and not (d.rule == "flag-no-writer" and d.message.startswith(waits))
              and not (d.rule == "start-never-requested" and d.message.startswith(never))]
    if errors:
        raise ReplayError(f"{run.path}: activity '{activity}' cannot be replayed: its replay's composition does not "
                          f"validate: {errors[0].message}")
    return rewritten, validated


def replay_activity(run: Run, activity: str, tolerance: float = 0.0, keep: Path | None = None) -> Replayed:
    """The activity replayed by its rewritten composition and judged; `keep`: a folder the files the
    replay's run leaves that its block promises are copied to (the hallway world's results)."""
    rewritten, validated = validated_rewrite(run, activity)
    rows = run.series(f"cycles/{activity}").publish_ns
    start = int(rows[0])
    origin = min([int(run.series(s).publish_ns[0]) for s in rewritten.inputs if len(run.series(s).publish_ns)]
                 + [start])
    pacing = RecordedCycles(run, rewritten, origin)
    with tempfile.TemporaryDirectory(prefix="hapticop-replay-") as scratch:
        run_dir = Path(scratch) / "run"
        options = RunOptions(clock="virtual", seed=run.seed, run_dir=run_dir, echo=False,
                             clock_start_ns=rewritten.start_ns, pacing=pacing)
        try:
            with blocks_of_a_recording(run.trusted, run.path.parent):
                run_system(validated, options, on_start=pacing.attach)
        except ReplayError:
            raise
        except Exception as error:  # noqa: BLE001 - a block's failure is the replay's finding, not a traceback
            raise ReplayError(f"{run.path}: activity '{activity}': its replay raised: "
                              f"{type(error).__name__}: {error}") from None
        replayed = _replayed_outputs(run, activity, run_dir, [stream for stream, _ in rewritten.outputs])
        if keep is not None:
            resolved = run.loaded.activities[activity]
            for name in resolved.block.promises(resolved.params):
                if (run_dir / name).exists():
                    shutil.copyfile(run_dir / name, Path(keep) / name)
    compared = [compare(stream, port, list(replayed[stream].values), replayed[stream].publish_ns.tolist(),
                        run.series(stream), tolerance, run.virtual, origin)
                for stream, port in rewritten.outputs]
    return Replayed(activity, run.loaded.activities[activity].spec.block, thread_of(run.loaded.composition)[activity],
                    len(rows), (start - origin) / 1e9, (int(rows[-1]) - origin) / 1e9, rewritten.inputs, compared,
                    pacing.diverged, pacing.computed)


def _replayed_outputs(run: Run, activity: str, run_dir: Path, streams: list[str]):
    files = sorted(run_dir.glob("*.mcap"))
    if not files:
        raise ReplayError(f"{run.path}: activity '{activity}': its replay left no recording of its outputs")
    try:
        return series_of(files[0], streams)
    except RecordingError as error:
        raise ReplayError(f"{run.path}: activity '{activity}': its replay's recording does not read: {error}") from None


def replay(path: Path, activities: list[str] | None = None, tolerance: float = 0.0,
           trusted: bool = False) -> list[Replayed]:
    """Replay the chosen activities of a recording, each from its own recorded inputs."""
    run = open_run(path, trusted)
    chosen = choose(run, list(activities or []))
    return [replay_activity(run, name, tolerance) for name in chosen]


def leaving_results(run: Run) -> list[str]:
    """The activities whose blocks leave files in the run directory when they clean (`promises`)."""
    return [name for name, resolved in run.loaded.activities.items() if resolved.block.promises(resolved.params)]


def results(path: Path | Run, run_dir: Path, tolerance: float = 0.0) -> tuple[list[Replayed], list[Path]]:
    """What the run's activities leave when they clean (the hallway world's trajectory, metrics and
    picture), made again from the recording: every activity whose block promises files is
    replayed, and the files it leaves are put in `run_dir`. Returns the replays and the files."""
    run = path if isinstance(path, Run) else open_run(path)
    activities = run.loaded.activities
    promising = leaving_results(run)
    if not promising:
        raise ReplayError(f"{run.path}: no activity of its composition leaves results (a block whose "
                          "`promises` names files, such as scene_world)")
    reasons = {name: why_not(run, name) for name in promising}
    able = [name for name, reason in reasons.items() if reason is None]
    if not able:
        name, reason = next(iter(reasons.items()))
        raise ReplayError(f"{run.path}: activity '{name}' cannot be replayed: {reason}")
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    replayed = [replay_activity(run, name, tolerance, keep=run_dir) for name in able]
    files = [run_dir / f for name in able for f in activities[name].block.promises(activities[name].params)
             if (run_dir / f).exists()]
    return replayed, files

