"""Where the emulated ropod truly is, for the simulated world, when the robot lives elsewhere.

With the pysoem driver the simulated robot is behind the smart wheels of the EtherCAT
emulator, in the emulator's own process; the master only sees wheel sensors, as on the
real robot. The simulated world still needs the true pose to judge the run and to place
the simulated LIDAR, so the emulator publishes it (hapticop.devices.ethercat.emulator.truth) and
this block reads it: ground truth of a simulation, never an input to a controller. (With the
sim driver, the simulated ropod is an activity, hapticop.sim.devices.ropod_plant, that
publishes the same two streams itself.)
"""

from __future__ import annotations

from pathlib import Path

from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Interface, Params, Port, RateRange


class RopodTruthParams(Params):
    interface: str = Field("hapticop-ecat0", description="the master's interface: the emulator publishes under it")
    path: str | None = Field(None, description="the emulator's --truth file, if not the default: the sandbox's "
                             "($HAPTICOP_ECAT_TRUTH), else /dev/shm/hapticop-ecat-<interface>.truth")


class RopodTruth(Block):
    Params = RopodTruthParams

    @classmethod
    def interface(cls, params: RopodTruthParams) -> Interface:
        return Interface(
            outputs={"robot_pose": Port("float64", (3,), "m, m, rad", "pose from where it started [x, y, theta]"),
                     "robot_twist": Port("float64", (3,), "m/s, m/s, rad/s", "true twist [vx, vy, wz]")},
            rate=RateRange(1.0, 4000.0),
        )

    def create(self) -> None:
        self.reader = None

    def configure_resources(self) -> None:
        from hapticop.devices.ethercat.emulator.truth import TruthReader, truth_path

        path = Path(self.params.path) if self.params.path else truth_path(self.params.interface)
        if not path.exists():
            raise RuntimeError(f"no emulated ropod publishes its pose at {path}: run the composition inside "
                               "'hapticop ethercat sandbox', which starts the emulator")
        self.reader = TruthReader(path)

    def compute(self) -> None:
        out = self.outputs
        if self.reader.read(out.robot_pose.value, out.robot_twist.value) > 0:
            out.robot_pose.publish()
            out.robot_twist.publish()

    def clean(self) -> None:
        if self.reader is not None:
            self.reader.close()
            self.reader = None
