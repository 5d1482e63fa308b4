"""Model-mediated rendering's predictor: the robot's motion from the scan's pose to the command's arrival.

It remembers the commands the operator's side sent and, each cycle, publishes how far they take the
robot from where it was when the scan in hand was taken to where it will be when the command sent
now arrives (``hapticop.haptics.prediction``); the haptic controller renders the scan from there.
"""

from __future__ import annotations

from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Params, Port, RateRange
from hapticop.haptics.prediction import CommandOdometry, PredictionParams


class PosePredictorParams(Params):
    prediction: PredictionParams = Field(default_factory=PredictionParams)


class PosePredictor(Block):
    """Dead reckoning of the commands sent, from the scan's time (its arrival less its crossing) minus the
    forward delay to now: the robot's travel [dx, dy, dθ] in the scan's frame."""

    Params = PosePredictorParams
    period_params = frozenset({"prediction.period_s"})
    inputs = {
        "command": Port("float64", (3,), "m/s, m/s, rad/s", "the twist [vx, vy, wz] sent to the robot"),
        "model_delay": Port("float64", (), "s", "how long the scan in hand took to arrive (a link's "
                            "<stream>_delay); unconnected: scans arrive at once", required=False),
        "round_trip": Port("float64", (), "s", "the measured round trip; unconnected or stale: twice "
                           "prediction.forward_delay_s", required=False),
    }
    outputs = {"travel": Port("float64", (3,), "m, m, rad", "the robot's motion from the scan's pose to the "
                              "command's arrival, in the scan's frame")}
    rate = RateRange(100.0, 2000.0, "commands are remembered at their own rate")

    def create(self) -> None:
        self.odometry = CommandOdometry(self.params.prediction)
        self.last_command_ns = -1

    def compute(self) -> None:
        inputs = self.inputs
        now_ns = self.clock.now_ns()
        command = inputs.command
        if command.seq and command.stamp_ns != self.last_command_ns:  # a command sent: it holds from its stamp
            self.last_command_ns = command.stamp_ns
            self.odometry.command(command.stamp_ns / 1e9, command.value)
        trip = inputs.round_trip
        forward_s = trip.value / 2.0 if trip.valid else self.params.prediction.forward_delay_s
        delay = inputs.model_delay
        scanned_s = (delay.stamp_ns / 1e9 - float(delay.value)) if delay.seq else now_ns / 1e9
        now_s = now_ns / 1e9
        self.odometry.travel(scanned_s - float(forward_s), now_s, self.outputs.travel.value)
        self.outputs.travel.publish()
