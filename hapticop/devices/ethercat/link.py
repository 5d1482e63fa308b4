"""The EtherCAT master's side of a segment: one process-data exchange, split around the cycle.

The master block sends the outputs (RxPDO images) at the end of a cycle and receives the
inputs (TxPDO images), the slaves' states and the working counter at the start of the next,
whatever carries them. `SoemLink` (hapticop.devices.ethercat.master) is a real segment
through SOEM; `DatagramSegment` is a simulated one: the images go over a `DatagramLink` to
the activity that simulates the segment, which answers with a `SegmentReply`.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from hapticop.devices.link import DatagramLink, MemoryLink


class SegmentLink(Protocol):
    expected_wkc: int  # the working counter of a healthy exchange

    def start(self, outputs: np.ndarray, inputs: np.ndarray) -> bool:
        """Bring the segment up (called every cycle until True); leaves outputs to send."""

    def send(self, outputs: np.ndarray) -> None:
        """The outputs, one row per wheel, onto the segment."""

    def receive(self, inputs: np.ndarray, states: np.ndarray) -> int:
        """The inputs and AL states the last `send` brought back; its working counter, or -1 if
        nothing came back."""

    def close(self, outputs: np.ndarray) -> None:
        """Send these (safe) outputs once more and let go of the segment."""


class SegmentReply:
    """What a simulated segment answers to a frame, in one datagram: the working counter
    (int32, little endian), each slave's AL state (a byte each, bus order), then the inputs."""

    def __init__(self, wheels: int, input_bytes: int, slaves: int):
        self.buffer = np.zeros(4 + slaves + wheels * input_bytes, np.uint8)
        self.working_counter = self.buffer[:4].view("<i4")
        self.states = self.buffer[4:4 + slaves]
        self.inputs = self.buffer[4 + slaves:].reshape(wheels, input_bytes)


class DatagramSegment:
    """The master's end of a simulated segment (the simulating activity answers every frame)."""

    def __init__(self, link: DatagramLink | MemoryLink, wheels: int, input_bytes: int, slaves: int):
        self.link = link
        self.reply = SegmentReply(wheels, input_bytes, slaves)
        self.expected_wkc = 3 * wheels  # each wheel's process data counts 3 (read and write)

    def start(self, outputs: np.ndarray, inputs: np.ndarray) -> bool:
        return True  # nothing to bring up: the simulated slaves are in OP

    def send(self, outputs: np.ndarray) -> None:
        self.link.send(outputs)

    def receive(self, inputs: np.ndarray, states: np.ndarray) -> int:
        """The newest reply waiting (a late one is superseded, as a frame would be)."""
        reply, size, got = self.reply, self.reply.buffer.nbytes, 0
        while (n := self.link.receive_into(reply.buffer)) > 0:
            if n != size:
                raise ValueError(f"the simulated segment answered {n} bytes, the master expects {size} "
                                 f"({len(reply.states)} slaves, {len(inputs)} wheels)")
            got = n
        if not got:
            return -1
        np.copyto(inputs, reply.inputs)
        np.copyto(states, reply.states)
        return int(reply.working_counter[0])

    def close(self, outputs: np.ndarray) -> None:
        self.link.send(outputs)
        self.link.close()
