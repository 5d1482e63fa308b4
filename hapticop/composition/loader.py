"""From a YAML tree to a typed composition with every block resolved.

The standard coordination a file declares is written out here, as nets and flag maps beside
the hand-written ones (`standard`), so the checks and the runtime see only ordinary nets.

Schema errors do not stop the checking: a broken entry (one thread, one activity...) is
set aside and the rest is validated, so the user sees all mistakes at once. References to
set-aside entries are not reported again as "unknown".
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field

from pydantic import ValidationError

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Interface, Params
from hapticop.blocks.registry import UnknownBlock, resolve
from hapticop.composition import ros2streams
from hapticop.composition.description import COLLECTIONS, VERSION, Activity, Composition
from hapticop.composition.diagnostics import Diagnostic, Path, Severity
from hapticop.composition.model_errors import diagnostics_from
from hapticop.composition.standard import Expansion, clashes, expand


@dataclass
class ResolvedActivity:
    name: str
    spec: Activity
    block: type[Block]
    params: Params
    interface: Interface


@dataclass
class Loaded:
    """A composition as far as it could be read, plus what went wrong reading it."""

    composition: Composition | None
    activities: dict[str, ResolvedActivity] = field(default_factory=dict)
    broken: set[tuple[str, str]] = field(default_factory=set)  # (collection, name) set aside
    diagnostics: list[Diagnostic] = field(default_factory=list)
    expansion: Expansion = field(default_factory=Expansion)  # what coordination.standard was written out as
    scheduled_by_broken: set[str] = field(default_factory=set)  # activities a set-aside thread schedules

    def is_broken(self, collection: str, name: str) -> bool:
        return (collection, name) in self.broken

    def scheduled_elsewhere(self, activity: str) -> bool:
        """Named in a set-aside thread's schedules: it may well run once that thread is mended."""
        return activity in self.scheduled_by_broken


def load_tree(tree: dict) -> Loaded:
    broken: set[tuple[str, str]] = set()
    tree, diagnostics = ros2streams.expand(tree, declared_port)
    work = copy.deepcopy(tree)
    composition = None
    for _ in range(4):  # each pass sets aside the entries the previous one found broken
        try:
            composition = Composition.model_validate(work)
            break
        except ValidationError as error:
            found = diagnostics_from(error, Composition)
            emptied = {tuple(c.split(".")) for c, _ in broken}
            # Setting entries aside may empty a collection; that is not a second mistake.
            found = [d for d in found if tuple(d.path) not in emptied]
            diagnostics.extend(d for d in found if d not in diagnostics)
            if not found:
                break
            if not _set_aside(work, found, broken):
                break
    loaded = Loaded(composition=composition, broken=broken, diagnostics=diagnostics,
                    scheduled_by_broken=_scheduled_by_broken(tree, broken))
    if composition is not None:
        _expand_standard(loaded)
        _resolve_activities(loaded)
    return loaded


def declared_port(tree: dict, ref: str):
    """The port `activity.port` names in `tree`, from its block's declaration; None when that cannot be told
    (the activity's own findings say why). A ROS 2 option without a shape takes the port's (ros2streams)."""
    activity, _, port = ref.partition(".")
    spec = (tree.get("activities") or {}).get(activity) if isinstance(tree, dict) else None
    if not isinstance(spec, dict):
        return None
    try:
        block = resolve(spec.get("block"))
        interface = block.declare(block.Params.model_validate(spec.get("params") or {}))
    except Exception:  # noqa: BLE001 - an unknown block or bad parameters: reported where they are written
        return None
    return {**interface.inputs, **interface.outputs}.get(port)


def _scheduled_by_broken(tree: dict, broken: set[tuple[str, str]]) -> set[str]:
    """The activities the set-aside threads' schedules name, read from the tree as written."""
    threads = tree.get("threads") if isinstance(tree, dict) else None
    names: set[str] = set()
    for collection, name in broken:
        spec = threads.get(name) if collection == "threads" and isinstance(threads, dict) else None
        schedules = spec.get("schedules") if isinstance(spec, dict) else None
        for members in schedules.values() if isinstance(schedules, dict) else ():
            if isinstance(members, list):
                names.update(m for m in members if isinstance(m, str))
    return names


def _expand_standard(loaded: Loaded) -> None:
    """Merge what `coordination.standard` stands for; with a clash, merge nothing and check the rest."""
    coordination = loaded.composition.coordination
    expansion = expand(loaded.composition)
    refused = expansion.diagnostics + clashes(expansion, coordination)
    loaded.diagnostics.extend(refused)
    if refused:  # the coordination is incomplete: its checks would only report follow-on findings
        loaded.broken.add(("coordination.standard", "standard"))
        return
    loaded.expansion = expansion
    loaded.composition.coordination = expansion.merged_into(coordination)


def _set_aside(work: dict, found: list[Diagnostic], broken: set[tuple[str, str]]) -> bool:
    """Remove the entries named by `found` from `work`; False when an error is not in one."""
    for diagnostic in found:
        if len(diagnostic.path) == 1 and diagnostic.rule in ("unknown-key", "bad-version"):
            # A stray top-level key or an unsupported version: check the rest as version 1.
            if diagnostic.rule == "unknown-key":
                work.pop(diagnostic.path[0], None)
            else:
                work["version"] = VERSION
            continue
        entry = _entry_of(diagnostic.path)
        if entry is None:
            return False
        collection, name = entry
        container = work
        for part in collection:
            container = container.get(part) if isinstance(container, dict) else None
        if not isinstance(container, dict):
            return False
        container.pop(name, None)
        broken.add((".".join(collection), str(name)))
    return True


def _entry_of(path: Path) -> tuple[tuple[str, ...], str] | None:
    for collection in sorted(COLLECTIONS, key=len, reverse=True):
        n = len(collection)
        if tuple(path[:n]) == collection and len(path) > n:
            return collection, path[n]
    return None


def _resolve_activities(loaded: Loaded) -> None:
    for name, spec in loaded.composition.activities.items():
        path = ("activities", name)
        try:
            block = resolve(spec.block)
        except UnknownBlock as error:
            loaded.diagnostics.append(
                Diagnostic(rule="unknown-block", message=error.reason, path=path + ("block",), hint=error.hint)
            )
            loaded.broken.add(("activities", name))
            continue
        if block is None:
            loaded.diagnostics.append(
                Diagnostic(rule="block-not-imported", severity=Severity.WARNING, path=path + ("block",),
                           message=f"block '{spec.block}' was found but not imported, so its parameters and "
                           "ports are not checked", hint="validate with --import-blocks to run its module and check it")
            )
            loaded.broken.add(("activities", name))
            continue
        try:
            params = block.Params.model_validate(spec.params)
        except ValidationError as error:
            loaded.diagnostics.extend(diagnostics_from(error, block.Params, prefix=path + ("params",)))
            loaded.broken.add(("activities", name))
            continue
        try:
            interface = block.declare(params)
        except Exception as error:  # noqa: BLE001 - an author's block: its failure is a finding, not a crash
            loaded.diagnostics.append(Diagnostic(
                rule="block-declaration", path=path + ("block",),
                message=f"block '{spec.block}' could not declare its ports for these parameters: "
                        f"{type(error).__name__}: {error}"))
            loaded.broken.add(("activities", name))
            continue
        both = sorted(set(interface.inputs) & set(interface.outputs))
        if both:  # a stream names a port by activity and name alone: it would not know which one
            loaded.diagnostics.append(Diagnostic(
                rule="block-declaration", path=path + ("block",),
                message=f"block '{spec.block}' declares {', '.join(repr(p) for p in both)} as both an input and "
                        "an output port", hint="a block's port names must differ: rename one (e.g. 'demand' in, "
                        "'force' out)"))
            loaded.broken.add(("activities", name))
            continue
        loaded.activities[name] = ResolvedActivity(name, spec, block, params, interface)
