"""Modes: each one's values valid for its activities, alone and with every other mode, and live.

A mode changes parameters while the system runs, between two cycles, without taking an
activity out of running; so each value must be one the block retunes live, the merged
parameters must validate, and the activity's ports must stay what the streams were wired to.
Modes that hold together merge in declaration order; every such combination is checked too
(up to `COMBINED_UP_TO` modes, beyond which only each mode alone).
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator, Mapping
from typing import Any

from pydantic import ValidationError

from hapticop.composition import graph as G
from hapticop.composition.diagnostics import Diagnostic
from hapticop.composition.model_errors import diagnostics_from
from hapticop.validation.changes import plain_value

COMBINED_UP_TO = 6


def merged(base: Mapping[str, Any], *overlays: Mapping[str, Any]) -> dict[str, Any]:
    """`base` with each overlay's values merged over it, mappings key by key, anything else replaced."""
    result = dict(plain_value(base))
    for overlay in overlays:
        for key, value in plain_value(overlay).items():
            if isinstance(value, dict) and isinstance(result.get(key), dict):
                result[key] = merged(result[key], value)
            else:
                result[key] = value
    return result


def modes(cg: G.CompositionGraph) -> Iterator[Diagnostic]:
    comp = cg.loaded.composition
    for name, mode in comp.modes.items():
        for activity, values in mode.params.items():
            path = ("modes", name, "params", activity)
            if activity not in comp.activities:
                known = ", ".join(sorted(comp.activities))
                yield Diagnostic("unknown-activity", f"mode '{name}' sets parameters of unknown activity '{activity}'",
                                 path, hint=f"activities: {known}")
                continue
            resolved = cg.loaded.activities.get(activity)
            if resolved is None:
                continue  # set aside (unknown block...): reported where it is declared
            block = resolved.block
            not_live = sorted(set(values) - block.running_params)
            if not_live:
                yield Diagnostic("mode-not-live", f"mode '{name}' changes {', '.join(repr(k) for k in not_live)} of "
                                 f"'{activity}', which block '{resolved.spec.block}' cannot retune while running",
                                 path + (not_live[0],),
                                 hint="a mode may change only parameters the block retunes live: "
                                      + (", ".join(sorted(block.running_params)) or "this block has none"))
                continue
            try:
                params = block.Params.model_validate(merged(resolved.spec.params, values))
            except ValidationError as error:
                yield from diagnostics_from(error, block.Params, prefix=path)
                continue
            if block.declare(params) != resolved.interface:
                yield Diagnostic("mode-changes-ports", f"mode '{name}' would change the ports of '{activity}'", path)
    yield from _combinations(cg)


def _combinations(cg: G.CompositionGraph) -> Iterator[Diagnostic]:
    """Modes valid alone may still clash when they hold together (a bound between two values)."""
    comp = cg.loaded.composition
    names = list(comp.modes)[:COMBINED_UP_TO]
    for size in range(2, len(names) + 1):
        for together in itertools.combinations(names, size):
            for activity in sorted({a for n in together for a in comp.modes[n].params}):
                resolved = cg.loaded.activities.get(activity)
                setting = [comp.modes[n].params[activity] for n in together if activity in comp.modes[n].params]
                if resolved is None or len(setting) < 2:
                    continue
                try:
                    resolved.block.Params.model_validate(merged(resolved.spec.params, *setting))
                except ValidationError as error:
                    first = error.errors()[0]
                    yield Diagnostic("mode-combination", f"modes {', '.join(together)} holding together leave "
                                     f"'{activity}' with invalid parameters: {first['msg']}",
                                     ("modes", together[-1], "params", activity))
                    return


CHECKS = (modes,)
