"""Modes in a running system: parameter values that hold while their flag is true.

Between two main-thread cycles the system looks at the modes' flags (a few memory reads);
when the set of modes that hold changes, or a live patch replaced the description, each
activity a mode touches gets its parameters merged afresh (its own, then every holding
mode's in declaration order) and takes them before its next step, like a live retune:
validation made sure they are all parameters the block retunes while running.
"""

from __future__ import annotations

from pydantic import ValidationError

from hapticop.runtime.described import Description
from hapticop.runtime.live import LiveTarget, retune
from hapticop.validation.modes import merged


class Modes:
    def __init__(self, target: LiveTarget, flag_index: dict[str, int], flags):
        self.target, self.flag_index, self.flags = target, flag_index, flags
        self.description: Description | None = None
        self.watched: list[tuple[str, int]] = []  # (mode, flag index) in declaration order
        self.holding: tuple[str, ...] = ()
        self.given: dict[str, object] = {}  # activity -> the parameters it was last given

    @property
    def names(self) -> tuple[str, ...]:
        return self.holding

    def apply_due(self) -> None:
        description = self.target.description
        if description is not self.description:  # started, or a live patch replaced it
            self.description = description
            self.watched = [(name, self.flag_index[mode.when]) for name, mode in description.composition.modes.items()
                            if mode.when in self.flag_index]
            self.given = {}
            self.holding = ()
            changed_description = True
        else:
            changed_description = False
        flags = self.flags
        holding = tuple(name for name, index in self.watched if flags[index])
        if holding == self.holding and not changed_description:
            return
        if holding != self.holding:
            left, entered = set(self.holding) - set(holding), set(holding) - set(self.holding)
            self.target.log.always("modes: %s%s%s", "entered " + ", ".join(sorted(entered)) if entered else "",
                                   "; " if entered and left else "", "left " + ", ".join(sorted(left)) if left else "")
        self.holding = holding
        self._give(description, holding)

    def _give(self, description: Description, holding: tuple[str, ...]) -> None:
        modes = description.composition.modes
        touched = sorted({a for mode in modes.values() for a in mode.params})
        for activity in touched:
            resolved = description.activities.get(activity)
            if resolved is None:
                continue
            overlays = [modes[name].params[activity] for name in holding if activity in modes[name].params]
            try:
                params = resolved.block.Params.model_validate(merged(resolved.spec.params, *overlays))
            except ValidationError as error:  # validation checked the combinations it could; say so, keep going
                self.target.log.error("modes %s: '%s' keeps its parameters: %s", ", ".join(holding), activity,
                                      error.errors()[0]["msg"])
                continue
            before = self.given.get(activity, resolved.params)
            if params == before:
                continue
            changed = frozenset(k for k in type(params).model_fields if getattr(params, k) != getattr(before, k))
            retune(self.target, description, activity, params, changed)
            self.given[activity] = params
