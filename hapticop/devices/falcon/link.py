"""How the Falcon block reaches a Falcon: command frames out, status frames in, over some link.

The block runs the same cycle whatever carries the frames: a real Falcon on USB (`usb_link`),
or an activity that simulates one and answers on a `DatagramLink` (`DatagramFalconLink`). Both
speak the 16-byte frames of the real codec, so the simulated path exercises the block's whole
protocol: homing bits, encoder counts, checksums, lost and corrupted frames.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from hapticop.devices.falcon.codec import FRAME_SIZE, FrameCodec, FrameError, Status, new_frame
from hapticop.devices.link import DatagramLink, MemoryLink

__all__ = ["FalconLink", "DatagramFalconLink"]


class FalconLink(Protocol):
    """One Falcon as the block sees it; none of these may block the block's 1 kHz cycle."""

    def ready(self) -> bool:
        """True once frames can flow; False while the link is still opening (asked each cycle)."""

    def send(self, command: NDArray[np.uint8]) -> None:
        """Send one command frame (lost frames are the link's to count, not to raise)."""

    def receive(self, status: Status) -> bool:
        """Decode the reply to the last command into `status`; True if a new, valid one came."""

    def close(self) -> None:
        """Let go of the device; safe while still opening and safe twice."""


class DatagramFalconLink:
    """Falcon frames to and from the activity that simulates the Falcon, one datagram each."""

    def __init__(self, link: DatagramLink | MemoryLink) -> None:
        self.link = link
        self.codec = FrameCodec()
        self.frame = new_frame()
        self.rejected = 0  # datagrams that were no valid status frame (a corrupted reply)

    def ready(self) -> bool:
        return True  # a datagram socket: nothing to wait for (frames sent to an absent peer are lost)

    def send(self, command: NDArray[np.uint8]) -> None:
        self.link.send(command)

    def receive(self, status: Status) -> bool:
        """Every reply waiting, the newest valid one kept (the simulator may answer late)."""
        got = False
        while n := self.link.receive_into(self.frame):
            try:
                if n == FRAME_SIZE:  # a longer datagram arrives cut to the frame's 16 bytes
                    self.codec.decode_status(self.frame, status)
                    got = True
                    continue
            except FrameError:
                pass
            self.rejected += 1
        return got

    def close(self) -> None:
        self.link.close()
