"""A composition's scripted patches replayed in time order: each must apply, validate and be live-able."""

from __future__ import annotations

from collections.abc import Iterator

from hapticop.composition.diagnostics import Diagnostic
from hapticop.composition.loader import Loaded
from hapticop.composition.yamlsource import Source
from hapticop.validation.patches import PatchError, prepare


def scripted_patches(source: Source, loaded: Loaded, state_limit: int) -> Iterator[Diagnostic]:
    """The first patch that would be refused, as a finding on its `patch` entry (the rest
    build on it, so they are not tried)."""
    tree, composition = source.tree, loaded.composition
    for name, scripted in sorted(composition.patches.items(), key=lambda item: (item[1].at, item[0])):
        try:
            tree, composition, _, _ = prepare(tree, scripted.patch, old=composition, patch_file=f"patches.{name}",
                                              state_limit=state_limit)
        except PatchError as error:
            first = error.diagnostics[0]
            detail = f"{first.dotted_path}: {first.message}" if first.path else first.message
            yield Diagnostic(rule="scripted-patch", message=f"patch '{name}' would be refused: {detail}",
                             path=("patches", name, "patch"))
            return
