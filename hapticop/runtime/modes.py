"""Modes in a running system: parameter values that hold while their flag is true.

Between two main-thread cycles the system looks at the modes' flags (a few memory reads);
when the set of modes that hold changes, or a live patch replaced the description, each
activity a mode touches gets its parameters merged afresh (its own, then every holding
mode's in declaration order) and takes them before its next step, like a live retune:
validation made sure they are all parameters the block retunes while running.
"""

from __future__ import annotations

from collections.abc import Callable

from pydantic import ValidationError

from hapticop.runtime.described import Description
from hapticop.runtime.live import LiveTarget, retune
from hapticop.validation.modes import merged


class Modes:
    def __init__(self, target: LiveTarget, flag_index: dict[str, int], flags,
                 tell: Callable[[str, dict], None] = lambda kind, payload: None):
        """`tell(kind, payload)`: the run's observer hears of each switch (`Observer.event`)."""
        self.target, self.flag_index, self.flags, self.tell = target, flag_index, flags, tell
        self.description: Description | None = None
        self.watched: list[tuple[str, int]] = []  # (mode, flag index) in declaration order
        self.mask = 0  # bit k: the k-th watched mode holds
        self.holding: tuple[str, ...] = ()
        self.given: dict[str, object] = {}  # activity -> the parameters it was last given

    def apply_due(self) -> None:
        """Between two main cycles: a few flag reads, and work only when the modes that hold change."""
        description = self.target.description
        fresh = description is not self.description  # started, or a live patch replaced it
        if fresh:
            self.description = description
            self.watched = [(name, self.flag_index[mode.when]) for name, mode in description.composition.modes.items()
                            if mode.when in self.flag_index]
            self.given = {}
        if not self.watched and not fresh:
            return  # no modes: nothing to read, nothing made
        mask, flags = 0, self.flags
        for bit, (_, index) in enumerate(self.watched):
            if flags[index]:
                mask |= 1 << bit
        if mask == self.mask and not fresh:
            return
        holding = tuple(name for bit, (name, _) in enumerate(self.watched) if mask >> bit & 1)
        entered = [n for n in holding if n not in self.holding]
        left = [n for n in self.holding if n not in holding]
        if entered or left:
            self.target.log.always("modes: %s", "; ".join(
                part for part in ("entered " + ", ".join(entered) if entered else "",
                                  "left " + ", ".join(left) if left else "") if part))
            self.tell("mode", {"entered": entered, "left": left, "holding": list(holding),
                               "modes": ", ".join(holding) or "none"})
        self.mask, self.holding = mask, holding
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
