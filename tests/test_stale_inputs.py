"""A stream whose every sample arrives older than its max_age says so in its reader's log, with the
age and the deadline, once and then every 10 s while it lasts; a link within the deadline says nothing.

The link here stamps what it delivers with the send time, as a network bridge does, so a 70 ms link
in front of a 50 ms deadline is what a newcomer met: the robot never moved, and nothing said why.
"""

from __future__ import annotations

import re

import pytest

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Port
from hapticop.runtime.context import STALE_IN_A_ROW

from .runtime_helpers import compose


class Reader(Block):
    """Counts the cycles it saw a valid sample (into a file, read by the test after the run)."""

    inputs = {"sample": Port("float64", (3,), "1")}

    def create(self):
        self.valid = 0

    def compute(self):
        port = self.inputs.sample
        if port.queue:  # every sample, in order
            while port.pop():
                self.valid += port.valid
        else:
            self.valid += port.valid

    def clean(self):
        (self.run_dir / "valid.txt").write_text(str(self.valid))


def linked(delay_s: float, max_age: str, stamp: str = "sent", policy: str = "{kind: latest}") -> str:
    return f"""
    version: 1
    threads:
      main: {{period: 1ms, deploy: main, schedules: {{0: [mediator, source, link, reader]}}}}
    activities:
      mediator: {{block: mediator}}
      source: {{block: "tests.blocks:Noise"}}
      link:
        block: link
        params:
          streams: {{sample: {{shape: [3]}}}}
          link: {{delay_s: {delay_s}}}
          stamp: {stamp}
      reader: {{block: "tests.test_stale_inputs:Reader"}}
    streams:
      sent: {{from: source.sample, to: [link.sample]}}
      received: {{from: link.sample_received, to: [reader.sample], max_age: {max_age}, policy: {policy}}}
    """


def _warnings(run):
    return re.findall(r"([0-9.]+) warning input 'sample': every sample arrives stale: ([0-9.]+) ms old on arrival, "
                      r"max_age 50.0 ms \(([0-9]+) in a row\)", (run / "reader.log").read_text())


@pytest.mark.parametrize("policy", ["{kind: latest}", "{kind: queue, capacity: 4}"])
def test_a_link_slower_than_the_deadline_is_said_with_age_and_deadline_rate_limited(tmp_path, policy):
    result = compose(tmp_path, linked(0.07, "50ms", policy=policy), duration="25s")
    run = tmp_path / "run-c"
    assert (run / "valid.txt").read_text() == "0"  # the reader never had a sample: the robot never moved
    said = _warnings(run)
    # at the third stale sample, then every 10 s: at 0.07 s, about 10 s and about 20 s of 25 s
    assert len(said) == 3, (run / "reader.log").read_text()
    assert all(abs(float(age) - 70.0) < 1.5 for _, age, _ in said)
    times = [float(t) for t, _, _ in said]
    assert times[0] < 0.1 and all(later - earlier >= 10.0 for earlier, later in zip(times, times[1:]))
    runs = [int(n) for _, _, n in said]
    assert runs[0] == STALE_IN_A_ROW and runs[0] < runs[1] < runs[2]
    assert result.outcome.status == 0


@pytest.mark.parametrize(("delay_s", "stamp"), [(0.03, "sent"), (0.07, "arrival")])
def test_a_link_within_the_deadline_says_nothing(tmp_path, delay_s, stamp):
    """Within the deadline, or stamped on arrival (the link's default: age counted from there)."""
    compose(tmp_path, linked(delay_s, "50ms", stamp), duration="2s")
    run = tmp_path / "run-c"
    assert int((run / "valid.txt").read_text()) > 1000
    assert "stale" not in (run / "reader.log").read_text()
