"""The names of every flag a composition has, and who writes and who reads each.

A flag is a boolean with one writer and at least one reader. Flags are named by their
owner:

- `<activity>.lcsm.<state>` (level, written by the activity's LCSM), e.g. `falcon.lcsm.running`;
  `<activity>.lcsm.<progress>` (event, written by the activity), e.g.
  `falcon.lcsm.resource_configuration_complete`; `<activity>.lcsm.request_<state>` (written
  by a flag map, read by the activity).
- `<activity>.<flag>` for the flags a block declares it writes or reads.
- `threads.<thread>.lcsm.*` likewise for a thread's LCSM; `threads.<thread>.schedule.<id>`
  (level: that schedule is selected), `threads.<thread>.select_schedule.<id>` (request),
  `threads.<thread>.deadline_missed` (event), `threads.<thread>.lost` (level: its process died).
- `system.shutdown_requested` (event: Ctrl+C or SIGTERM), `system.stop` (read by the runtime:
  shut down as if Ctrl+C had been pressed, so a net can end a run) and `system.exit` (read by
  the runtime: leave the process).
- `flags.<name>`: coupling flags declared under `coordination.flags`, written by one flag
  map and read by another, as the thesis couples its three nets.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from hapticop.composition import lcsm

RUNTIME = "the runtime"


@dataclass
class FlagInfo:
    """Who writes and who reads one flag (parties are human-readable names)."""

    name: str
    writers: list[str] = field(default_factory=list)
    readers: list[str] = field(default_factory=list)
    declared_by: str = ""  # the party whose declaration created the flag


def lcsm_flags(prefix: str, owner: str) -> dict[str, FlagInfo]:
    flags: dict[str, FlagInfo] = {}
    for name in lcsm.STATE_FLAGS + lcsm.PROGRESS_FLAGS:
        flags[f"{prefix}.lcsm.{name}"] = FlagInfo(f"{prefix}.lcsm.{name}", writers=[owner], declared_by=owner)
    for name in lcsm.REQUEST_FLAGS:
        flags[f"{prefix}.lcsm.{name}"] = FlagInfo(f"{prefix}.lcsm.{name}", readers=[owner], declared_by=owner)
    return flags


def thread_flags(thread: str, schedule_ids: list[int]) -> dict[str, FlagInfo]:
    owner = f"thread '{thread}'"
    prefix = f"threads.{thread}"
    flags = lcsm_flags(prefix, owner)
    for sid in schedule_ids:
        flags[f"{prefix}.schedule.{sid}"] = FlagInfo(f"{prefix}.schedule.{sid}", writers=[owner], declared_by=owner)
        flags[f"{prefix}.select_schedule.{sid}"] = FlagInfo(
            f"{prefix}.select_schedule.{sid}", readers=[owner], declared_by=owner
        )
    flags[f"{prefix}.deadline_missed"] = FlagInfo(f"{prefix}.deadline_missed", writers=[owner], declared_by=owner)
    flags[f"{prefix}.lost"] = FlagInfo(f"{prefix}.lost", writers=[owner], declared_by=owner)
    return flags


def activity_flags(activity: str, written: dict[str, str], read: dict[str, str]) -> dict[str, FlagInfo]:
    owner = f"activity '{activity}'"
    flags = lcsm_flags(activity, owner)
    for name in written:
        flags[f"{activity}.{name}"] = FlagInfo(f"{activity}.{name}", writers=[owner], declared_by=owner)
    for name in read:
        flags[f"{activity}.{name}"] = FlagInfo(f"{activity}.{name}", readers=[owner], declared_by=owner)
    return flags


def system_flags() -> dict[str, FlagInfo]:
    return {
        "system.shutdown_requested": FlagInfo("system.shutdown_requested", writers=[RUNTIME], declared_by=RUNTIME),
        "system.exit": FlagInfo("system.exit", readers=[RUNTIME], declared_by=RUNTIME),
        "system.stop": FlagInfo("system.stop", readers=[RUNTIME], declared_by=RUNTIME),
    }


def coupling_flags(names: list[str]) -> dict[str, FlagInfo]:
    return {f"flags.{n}": FlagInfo(f"flags.{n}", declared_by="coordination.flags") for n in names}
