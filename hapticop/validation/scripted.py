"""A composition's scripted patches replayed in time order: each must apply, validate and be live-able."""

from __future__ import annotations

from collections.abc import Iterator

from hapticop.composition import flags as flagdefs
from hapticop.composition.description import SPARE_ACTIVITIES, SPARE_FLAGS
from hapticop.composition.diagnostics import Diagnostic
from hapticop.composition.loader import Loaded
from hapticop.composition.yamlsource import Source
from hapticop.validation.patches import PatchError, prepare


def scripted_patches(source: Source, loaded: Loaded, state_limit: int) -> Iterator[Diagnostic]:
    """The first patch that would be refused, as a finding on its `patch` entry (the rest
    build on it, so they are not tried). Added activities and flags are counted over all of them
    against the room a running system keeps for them."""
    tree, composition = source.tree, loaded.composition
    added_activities, added_flags = 0, set()
    for name, scripted in sorted(composition.patches.items(), key=lambda item: (item[1].at, item[0])):
        try:
            prepared = prepare(tree, scripted.patch, old=composition, patch_file=f"patches.{name}",
                               state_limit=state_limit)
        except PatchError as error:
            first = error.diagnostics[0]
            detail = f"{first.dotted_path}: {first.message}" if first.path else first.message
            yield Diagnostic(rule="scripted-patch", message=f"patch '{name}' would be refused: {detail}",
                             path=("patches", name, "patch"))
            return
        tree, composition = prepared.tree, prepared.composition
        added_activities += len(prepared.plan.added_activities)
        for activity in prepared.plan.added_activities:
            iface = prepared.loaded.activities[activity].interface
            added_flags |= set(flagdefs.activity_flags(activity, iface.flags_written, iface.flags_read))
        if added_activities > SPARE_ACTIVITIES or len(added_flags) > SPARE_FLAGS:
            yield Diagnostic(rule="scripted-patch", message=f"patch '{name}' would be refused: the scripted patches "
                             f"add {added_activities} activities by then, and a running system has room for "
                             f"{SPARE_ACTIVITIES} added activities and {SPARE_FLAGS} added flags",
                             path=("patches", name, "patch"))
            return
