"""Parameter events: each new parameter set an activity is handed while running, recorded as `/parameters`.

Where new parameters land (`live.retune`, for a patch and a mode alike) says so in the system's
log, off the real-time path (`logs.LogWriter`); the recorder follows that file
(`observe/parameter_events.py`) and writes each event, numbered per activity in the order they
were handed, as the runner numbers them (`ActivityRunner.parameters`), so a replay knows from an
activity's recorded cycles which set its block held in each one.
"""

from __future__ import annotations

import json

from hapticop.runtime.logs import Logger

PREFIX = "parameters handed: "
LOG_FILE = "system.log"  # the owner whose logger `landed` is given (`System.log`)


def landed(log: Logger, activity: str, params, changed: frozenset[str]) -> None:
    """New parameters handed to `activity` (its runner numbers them in the same order)."""
    dumped = params.model_dump(mode="json")
    log.info("%s%s", PREFIX, json.dumps({"activity": activity, "parameters": dumped, "changed": sorted(changed),
                                           "diff": {name: dumped[name] for name in sorted(changed)}}))
