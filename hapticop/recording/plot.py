"""Recorded streams against time: a picture (matplotlib) or a CSV table.

A stream is named as in the composition (`handle_force`), or one element of it
(`scan_ranges[405]`, `robot_pose[2]`); time is the publish time, in seconds from the
recording's first sample.
"""

from __future__ import annotations

import csv
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hapticop.recording.reading import RecordingError, Series, series

MAX_LINES = 12  # a stream with more elements is plotted one chosen element at a time
_ELEMENT = re.compile(r"^(?P<name>[^\[\]]+)(\[(?P<index>\d+)\])?$")


@dataclass
class Selected:
    label: str
    series: Series
    columns: np.ndarray  # (samples, lines)
    names: list[str]


def select(path: Path, wanted: list[str]) -> list[Selected]:
    chosen = []
    cache: dict[str, Series] = {}
    for text in wanted:
        match = _ELEMENT.match(text.strip())
        if not match:
            raise RecordingError(f"'{text}' is not a stream name, nor one element of one (e.g. 'robot_pose[2]')")
        name = match["name"]
        found = cache.get(name) or series(path, name)
        cache[name] = found
        flat = found.values.reshape(len(found.values), -1)
        if match["index"] is not None:
            index = int(match["index"])
            if index >= flat.shape[1]:
                raise RecordingError(f"'{name}' has {flat.shape[1]} elements; element {index} does not exist")
            chosen.append(Selected(text, found, flat[:, index:index + 1], [f"{name}[{index}]"]))
        elif flat.shape[1] > MAX_LINES:
            raise RecordingError(f"'{name}' has {flat.shape[1]} elements per sample, too many lines for one plot; "
                                 f"choose one, e.g. '{name}[{flat.shape[1] // 2}]'")
        else:
            names = [name] if found.info.shape == () else [f"{name}[{i}]" for i in range(flat.shape[1])]
            chosen.append(Selected(text, found, flat, names))
    return chosen


def _origin(chosen: list[Selected]) -> int:
    starts = [int(s.series.publish_ns[0]) for s in chosen if len(s.series.publish_ns)]
    return min(starts) if starts else 0


def _open_for_writing(target: Path):
    """`target` opened to write text without waiting: a FIFO nobody reads is refused (ENXIO), not
    waited on; a directory too; a pipe with a reader, a file or a device is written as usual."""
    import fcntl

    descriptor = os.open(target, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NONBLOCK | os.O_NOCTTY, 0o666)
    flags = fcntl.fcntl(descriptor, fcntl.F_GETFL)
    fcntl.fcntl(descriptor, fcntl.F_SETFL, flags & ~os.O_NONBLOCK)  # a slow reader is waited for
    return os.fdopen(descriptor, "w", newline="")


def write_csv(chosen: list[Selected], target: Path) -> int:
    """One row per sample: stream, sequence, publish and log time (s), then its values; returns rows.
    `OSError` when the target cannot be written (a full device, a directory, a FIFO without a reader)."""
    origin = _origin(chosen)
    width = max(s.columns.shape[1] for s in chosen)
    rows = 0
    with _open_for_writing(target) as out:
        table = csv.writer(out)
        table.writerow(["stream", "sequence", "publish_time_s", "log_time_s", *[f"value[{i}]" for i in range(width)]])
        for s in chosen:
            times = (s.series.publish_ns - origin) / 1e9
            logged = (s.series.log_ns - origin) / 1e9
            for k in range(len(times)):
                table.writerow([s.label, int(s.series.sequence[k]), f"{times[k]:.9f}", f"{logged[k]:.9f}",
                                *[repr(float(v)) for v in s.columns[k]]])
                rows += 1
    return rows


def draw(chosen: list[Selected], target: Path | None, title: str) -> Path | None:
    """One panel per stream, sharing the time axis; on screen when there is one and no `target`."""
    import matplotlib

    if target is not None or not os.environ.get("DISPLAY"):
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    origin = _origin(chosen)
    figure, axes = plt.subplots(len(chosen), 1, sharex=True, squeeze=False, figsize=(9, 2.2 + 1.8 * len(chosen)))
    for axis, s in zip(axes[:, 0], chosen, strict=True):
        times = (s.series.publish_ns - origin) / 1e9
        for column, name in enumerate(s.names):
            axis.plot(times, s.columns[:, column], label=name, linewidth=0.8)
        unit = s.series.info.unit
        axis.set_ylabel(f"{s.label} [{unit}]" if unit and unit != "1" else s.label)
        if len(s.names) > 1:
            axis.legend(loc="upper right", fontsize="small", ncol=min(len(s.names), 4))
        axis.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel("publish time [s]")
    figure.suptitle(title, fontsize="medium")
    figure.tight_layout()
    if target is None and matplotlib.get_backend().lower() != "agg":
        plt.show()
        return None
    figure.savefig(target, dpi=110)
    plt.close(figure)
    return target
