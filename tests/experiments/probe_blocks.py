"""The experiment tests' probe block: a spring that can be told to crash or to hang, and leaves metrics.json."""

from __future__ import annotations

import json
import time
from typing import Literal

from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Params, Port


class SpringParams(Params):
    kp_n_per_m: float = Field(200.0, ge=0.0, le=3000.0, description="stiffness towards the centre")
    mode: Literal["ok", "raise", "hang"] = Field("ok", description="what the run does: finish, crash or hang")


class Spring(Block):
    """F = -k p; the largest force it commanded goes to metrics.json, which an experiment keeps."""

    Params = SpringParams
    inputs = {
        "position": Port("float64", (3,), "m", "handle position, device frame"),
        "velocity": Port("float64", (3,), "m/s", "handle velocity", required=False),
    }
    outputs = {"force": Port("float64", (3,), "N", "force on the handle, device frame")}

    def compute(self) -> None:
        if self.params.mode == "raise":
            raise RuntimeError("the probe was told to crash")
        if self.params.mode == "hang":
            time.sleep(3600)
        position, force = self.inputs.position, self.outputs.force
        if position.valid:
            force.value[:] = position.value
            force.value *= -self.params.kp_n_per_m
            self.peak = max(getattr(self, "peak", 0.0), float(abs(force.value).max()))
        else:
            force.value[:] = 0.0
        force.publish()

    def clean(self) -> None:
        self.outputs.force.value[:] = 0.0
        self.outputs.force.publish()
        if self.run_dir is not None:
            (self.run_dir / "metrics.json").write_text(json.dumps({"force_peak_n": getattr(self, "peak", 0.0),
                                                                  "kp": self.params.kp_n_per_m}))
