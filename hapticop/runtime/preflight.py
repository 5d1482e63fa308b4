"""Before a run makes anything: is every device its activities need there? One answer for all.

Each activity's block is asked (`Block.preflight`) on a thread of its own, all at once, so the
whole check takes as long as the slowest device and never longer than the bound: a LIDAR that
does not answer at its address costs the bound once, not once per device. Blocks know nothing
of each other; the run only gathers what each says is missing.
"""

from __future__ import annotations

import threading
import time

from hapticop.blocks.base import Block
from hapticop.composition.loader import Loaded

PREFLIGHT_TIMEOUT_S = 3.0


class DevicesMissing(RuntimeError):
    """Devices the composition needs are not there: the run was not started."""

    def __init__(self, system: str, missing: dict[str, str]):
        self.missing = missing
        lines = "".join(f"\n  {name}: {problem}" for name, problem in missing.items())
        super().__init__(f"{system} not started: {len(missing)} of its devices "
                         f"{'is' if len(missing) == 1 else 'are'} not there{lines}")


def missing_devices(loaded: Loaded, timeout_s: float = PREFLIGHT_TIMEOUT_S) -> dict[str, str]:
    """What each activity cannot find, by activity (file order); empty when everything is there."""
    asked = {name: resolved for name, resolved in loaded.activities.items()
             if resolved.block.preflight.__func__ is not Block.preflight.__func__}
    answers: dict[str, str | None] = {}

    def ask(name: str) -> None:
        resolved = asked[name]
        try:
            answers[name] = resolved.block.preflight(resolved.params, timeout_s)
        except Exception as error:  # noqa: BLE001 - a check that breaks says so instead of stopping the others
            answers[name] = f"the check itself failed: {type(error).__name__}: {error}"

    threads = {name: threading.Thread(target=ask, args=(name,), name=f"hapticop-preflight {name}", daemon=True)
               for name in asked}
    for thread in threads.values():
        thread.start()
    deadline = time.monotonic() + timeout_s + 1.0  # each check keeps its own bound; this one is the last word
    for thread in threads.values():
        thread.join(max(0.0, deadline - time.monotonic()))
    missing = {}
    for name in asked:
        if name not in answers:
            missing[name] = f"no answer within {timeout_s:g} s"
        elif answers[name]:
            missing[name] = answers[name]
    return missing
