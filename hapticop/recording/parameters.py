"""A recording's parameter events (`/parameters`), as ROS 2's `/parameter_events`: every new set of
parameters an activity was handed while running (a live patch's retune, a mode's), in order.

Each message is JSON: the activity, its revision (the how-manieth set handed to it, from 1: what
its recorded cycles' `parameters` column names when it holds that set), the new resolved
parameters, the names that changed and their new values (`diff`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from mcap.reader import make_reader

TOPIC = "/parameters"
SCHEMA = {
    "title": "hapticop.ParameterEvent", "type": "object",
    "description": "new parameters handed to a running activity (a live retune or a mode's)",
    "properties": {"activity": {"type": "string"}, "revision": {"type": "integer"},
                   "parameters": {"type": "object"}, "changed": {"type": "array", "items": {"type": "string"}},
                   "diff": {"type": "object", "description": "each changed parameter's new value"}},
}


@dataclass(frozen=True)
class ParameterEvent:
    activity: str
    revision: int
    parameters: dict
    changed: tuple[str, ...]
    time_ns: int  # when the recorder read it (the cycle it took effect in says the rest)


def events(path: Path) -> list[ParameterEvent]:
    """Every parameter event of a finished recording, in order (none in a recording without them)."""
    found = []
    with open(path, "rb") as stream:
        for _, _, message in make_reader(stream).iter_messages(topics=[TOPIC], log_time_order=False):
            event = json.loads(message.data)
            found.append(ParameterEvent(event["activity"], int(event["revision"]), event["parameters"],
                                        tuple(event["changed"]), message.log_time))
    return found
