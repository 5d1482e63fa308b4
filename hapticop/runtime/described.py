"""The running system's description, kept once: the tree patches apply to and what was loaded from it."""

from __future__ import annotations

from dataclasses import dataclass

from ruamel.yaml.comments import CommentedMap

from hapticop.composition.description import Composition
from hapticop.composition.loader import Loaded, ResolvedActivity
from hapticop.runtime.assembly import thread_of


@dataclass(frozen=True)
class Description:
    """Never changed in place: a live patch replaces the whole of it, in one assignment,
    at a cycle boundary, so the tree, the composition, the resolved activities and which
    thread owns each activity always agree."""

    tree: CommentedMap
    loaded: Loaded
    owner_thread: dict[str, str]  # activity -> the thread that schedules it
    revision: int = 0  # how many changes the running description has taken (status shows it)

    @classmethod
    def of(cls, tree: CommentedMap, loaded: Loaded, revision: int = 0) -> Description:
        return cls(tree, loaded, thread_of(loaded.composition), revision)

    @property
    def composition(self) -> Composition:
        return self.loaded.composition

    @property
    def activities(self) -> dict[str, ResolvedActivity]:
        return self.loaded.activities

    def patched(self, tree: CommentedMap, composition: Composition,
                resolved: dict[str, ResolvedActivity]) -> Description:
        """The description a patch leaves: its tree and composition, the activities it
        resolved (new parameters, added activities) over the ones kept."""
        return Description.of(tree, Loaded(composition, {**self.loaded.activities, **resolved}), self.revision + 1)
