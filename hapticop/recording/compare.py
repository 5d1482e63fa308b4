"""A replayed stream against its recording: sample by sample, by number, within a tolerance.

What `hapticop replay` prints per output stream: how many samples were compared, the largest
absolute difference, and where the first mismatch is (its time, its number, the element and both
values), so a regression is found where it starts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hapticop.recording.reading import Series


@dataclass
class Compared:
    """One output stream: the replayed samples against the recorded ones."""

    stream: str
    port: str
    samples: int  # compared
    max_diff: float
    mismatches: int  # samples beyond the tolerance (or published at another time)
    missing: int  # recorded samples the replay did not publish
    extra: int  # samples the replay published beyond the recorded ones
    first: str = ""  # where the first mismatch is, in words

    @property
    def ok(self) -> bool:
        return not (self.mismatches or self.missing or self.extra)


def _element(stream: str, shape: tuple[int, ...], flat_index: int) -> str:
    if not shape:
        return stream
    return f"{stream}[{', '.join(str(int(i)) for i in np.unravel_index(flat_index, shape))}]"


def compare(stream: str, port: str, values: list[np.ndarray], stamps_ns: list[int], recorded: Series,
            tolerance: float, same_times: bool, origin_ns: int) -> Compared:
    """The replayed samples (`values`, published at `stamps_ns`, numbered from 1) against the recorded
    ones with the same numbers: beyond `tolerance`, or (`same_times`) published at another time, they
    differ. Times in words are from `origin_ns`."""
    info = recorded.info
    n = len(values)
    size = int(np.prod(info.shape, dtype=np.int64))  # not -1: an empty replay has no length to infer it from
    replayed = (np.stack(values) if n else np.zeros((0, *info.shape), info.dtype)).reshape(n, size)
    replayed_stamps = np.asarray(stamps_ns, np.int64)
    index = recorded.sequence - 1  # the replayed sample with the recorded one's number
    have = (index >= 0) & (index < n)
    mine = replayed[index[have]].astype(np.float64)
    theirs = recorded.values.reshape(len(recorded.values), size)[have].astype(np.float64)
    both_nan = np.isnan(mine) & np.isnan(theirs)
    diff = np.where(both_nan, 0.0, np.abs(mine - theirs))
    diff[np.isnan(diff)] = math.inf  # one NaN, the other not
    worst = diff.max(axis=1) if diff.shape[1] else np.zeros(len(diff))
    bad = worst > tolerance
    late = replayed_stamps[index[have]] != recorded.publish_ns[have] if same_times else np.zeros(len(worst), bool)
    first = ""
    wrong = np.flatnonzero(bad | late)
    if len(wrong):
        k = int(wrong[0])
        number = int(recorded.sequence[have][k])
        at = (int(recorded.publish_ns[have][k]) - origin_ns) / 1e9
        if bad[k]:
            j = int(np.argmax(diff[k]))
            first = (f"at {at:.6f} s (sample {number}): {_element(stream, info.shape, j)} replayed "
                     f"{float(mine[k, j])!r}, recorded {float(theirs[k, j])!r}")
        else:
            first = (f"at {at:.6f} s (sample {number}): replayed at "
                     f"{(int(replayed_stamps[index[have]][k]) - origin_ns) / 1e9:.6f} s")
    last_recorded = int(recorded.sequence.max()) if len(recorded.sequence) else 0
    extra = max(0, n - last_recorded - (info.every - 1))
    missing = int((~have).sum())
    if not first and missing:
        number = int(recorded.sequence[~have][0])
        first = f"sample {number} and {missing - 1} more were recorded but not replayed"
    elif not first and extra:
        first = f"the replay published {extra} samples after the last recorded one"
    return Compared(stream, port, int(have.sum()), float(worst.max()) if len(worst) else 0.0,
                    int((bad | late).sum()), missing, extra, first)
