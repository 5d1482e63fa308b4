"""The block harness runs one block alone, as its activity would: a block author's test bench."""

from __future__ import annotations

import numpy as np
import pytest

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Params, Port
from hapticop.composition.lcsm import State
from hapticop.testing import BlockHarness, HookDidNotComplete


def test_an_input_fed_reaches_the_output_at_the_next_step():
    harness = BlockHarness("echo", {"dtype": "float64", "shape": [3]})
    harness.configure()
    harness.feed("input", [1.0, 2.0, 3.0])
    harness.step()
    assert harness.outputs.output.value.tolist() == [1.0, 2.0, 3.0]
    assert harness.outputs.output.published == 1
    harness.step(5)  # nothing new: nothing republished
    assert harness.outputs.output.published == 1 and harness.block.received == 1


class _WaitsParams(Params):
    cycles: int = 3


class _Waits(Block):
    """Needs a few cycles to configure, then writes in its flush what compute read."""

    Params = _WaitsParams
    inputs = {"setpoint": Port("float64", (), "m")}
    outputs = {"written": Port("float64", (), "m")}
    flags_written = {"ready": "configured"}

    def create(self):
        self.tries = 0

    def configure_resources(self):
        self.tries += 1
        self.log.info("try %d", self.tries)
        if self.tries < self.params.cycles:
            return False
        self.flags["ready"] = True
        return True

    def flush(self):
        self.outputs.written.value[...] = self.inputs.setpoint.value
        self.outputs.written.publish()


def test_configuration_hooks_are_called_again_one_period_apart_until_they_complete():
    """As the activity's LCSM does in a run: one hook a cycle (creation in the first, the resources
    in the next four, the capabilities in the sixth), and the first compute in the cycle after."""
    harness = BlockHarness(_Waits, {"cycles": 4})
    harness.configure()
    assert harness.block.tries == 4 and harness.flags["ready"]
    assert harness.clock.now_ns() == 6 * harness.period_ns
    assert harness.runner.state is State.RUNNING
    assert harness.log_lines() == ["info: try 1", "info: try 2", "info: try 3", "info: try 4"]
    harness.feed("setpoint", 0.25)
    harness.step()
    assert float(harness.outputs.written.value) == 0.25


def test_a_hook_that_never_completes_is_named():
    harness = BlockHarness(_Waits, {"cycles": 1000})
    with pytest.raises(HookDidNotComplete, match="configure_resources did not complete in 10 cycles"):
        harness.configure(max_cycles=10)


def test_parameters_are_validated_by_the_blocks_own_model():
    with pytest.raises(ValueError, match="cycles"):
        BlockHarness(_Waits, {"cycles": "many"})


def test_the_harness_ports_are_the_runtimes_own():
    harness = BlockHarness("echo", {"dtype": "int64"})
    harness.configure()
    harness.feed("input", np.int64(7))
    harness.step()
    assert int(harness.outputs.output.value) == 7 and harness.inputs.input.seq == 1


class _Fails(Block):
    inputs = {"x": Port("float64", (), "m")}

    def compute(self):
        if self.inputs.x.value > 1.0:
            raise ValueError("too far")


def test_a_failing_compute_raises_and_the_life_cycle_pauses_the_block_as_in_a_run():
    harness = BlockHarness(_Fails)
    harness.configure()
    harness.feed("x", 2.0)
    with pytest.raises(ValueError, match="too far"):
        harness.step()
    assert harness.runner.state is State.PAUSING
    assert harness.log_lines() == ["error: running failed: ValueError: too far"]
    harness.step()  # paused: compute is not called again until the mediator asks for running
    harness.clean()
    assert harness.runner.state is State.DONE
