"""Pings across an emulated link and back: the round trip, jitter and loss a single-host run measures.

On two hosts the bridges ping each other (docs/teleop.md). A run on one host with the link
emulated by `link` blocks has no bridge, so this block stands in for its pings: it sends a ping
(its slot and send time) through the link to the other side, whose streams echo it straight back
through the link the other way, and measures each echo as the bridge measures a pong
(`hapticop.network.clock`). So the round trip a predictor reads is the one the emulated link makes,
jitter and loss included, not a parameter.
"""

from __future__ import annotations

import json

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Params, Port
from hapticop.network.clock import OffsetEstimator, round_trip_rows

WINDOW = 64  # pings the figures look back over, as the bridge's


class RoundTripParams(Params):
    ping_period_s: float = Field(0.05, gt=0, description="a ping this often (the bridge's 50 ms)")


class RoundTrip(Block):
    """Sends a ping [slot, send time] each period and measures the echoes that come back: round trip (the
    median of the last 64), smoothed jitter and the fraction of pings unanswered, published once answered."""

    Params = RoundTripParams
    inputs = {"echo": Port("float64", (2,), "1, s", "a ping as it came back from the other side", required=False)}
    outputs = {
        "ping": Port("float64", (2,), "1, s", "[slot, send time] of the ping just sent"),
        "rtt": Port("float64", (), "s", "round trip (median of the last pings)"),
        "jitter": Port("float64", (), "s", "smoothed change of the round trip between pings"),
        "loss": Port("float64", (), "1", "fraction of the last pings not answered"),
    }

    def create(self) -> None:
        self.estimator = OffsetEstimator(WINDOW)
        self.pinged_at = [-1.0] * WINDOW
        self.next_ping_ns = 0
        self.pinged = self.answered = 0
        self.rtts = np.zeros(1 << 16)  # every echo's round trip (s), for the run's table

    def compute(self) -> None:
        now = self.clock.now_ns()
        echo, out = self.inputs.echo, self.outputs
        if echo.fresh:
            slot, sent_s = int(echo.value[0]), float(echo.value[1])
            if 0 <= slot < WINDOW and self.pinged_at[slot] == sent_s:  # not an echo of a slot since reused
                self.pinged_at[slot] = -1.0  # a duplicate echo is not a second answer
                self.estimator.echoed(slot, round(sent_s * 1e9), now)
                self.rtts[self.answered % len(self.rtts)] = self.estimator.last_rtt_ns / 1e9
                self.answered += 1
        if now < self.next_ping_ns:
            return
        self.next_ping_ns = now + round(self.params.ping_period_s * 1e9)
        slot = self.estimator.sent()
        self.pinged_at[slot] = now / 1e9
        out.ping.value[0], out.ping.value[1] = slot, now / 1e9
        out.ping.publish()
        self.pinged += 1
        estimator = self.estimator
        if estimator.synced:
            out.rtt.value[...] = estimator.rtt_ns / 1e9
            out.jitter.value[...] = estimator.jitter_ns / 1e9
            out.loss.value[...] = estimator.loss
            out.rtt.publish()
            out.jitter.publish()
            out.loss.publish()

    def clean(self) -> None:
        estimator = self.estimator
        self.log.info("round trip %.1f ms (median of the last %d pings); jitter %.1f ms; %d of %d pings unanswered",
                      estimator.rtt_ns / 1e6, WINDOW, estimator.jitter_ns / 1e6, self.pinged - self.answered,
                      self.pinged)
        if self.answered:
            self._write_table()

    def _write_table(self) -> None:
        """The link's figures over the run, as the bridge leaves them (printed with the run's other tables)."""
        rtts_ms = self.rtts[: min(self.answered, len(self.rtts))] * 1e3
        rows = round_trip_rows(rtts_ms, self.estimator.jitter_ns, self.answered, self.pinged)
        table = {"title": f"link measured by '{self.name}' (pings through the emulated link and back)", "rows": rows}
        (self.run_dir / f"results-link-{self.name}.json").write_text(json.dumps(table, indent=1))
