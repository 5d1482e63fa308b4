"""Where a world's scene comes from, and what is wrong with it, located.

A scene is written inline in the composition, or in a YAML file (a name alone, such as `H1`, is one of
the scenes shipped in `hapticop/sim/scenes/`; a path is found beside the composition the way a block
module beside it is), or is an MJCF file (`.xml`) for anything richer. Every finding names the file,
line and field it blames: a material nobody defined, a movable body without mass, static geometry that
overlaps, a robot that starts inside something, and a scene MuJoCo cannot load (its message, one line).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from pydantic import BaseModel, ConfigDict, ValidationError

from hapticop.blocks.registry import beside_folders
from hapticop.composition.diagnostics import Diagnostic
from hapticop.composition.model_errors import diagnostics_from
from hapticop.composition.yamlsource import SourceError, parse_text, read_text
from hapticop.sim.judge import Target
from hapticop.sim.scene import Scene, to_mjcf

SHIPPED = Path(__file__).resolve().parent / "scenes"
OVERLAP_M = 1e-4
"""Static geometry may touch (walls meeting at a corner); deeper than this it overlaps."""


@dataclass(frozen=True)
class Loaded:
    """A scene ready for the engine: its MJCF, and the scene model when it was written as one."""

    xml: str
    scene: Scene | None
    file: str  # where it came from ("" inline)
    places: dict[str, tuple[tuple, int]] = field(default_factory=dict)
    """A movable body's or handle's MJCF name: its path in the scene (and a body's name, if it has one) and its
    line in `file` (0: unknown)."""

    def where(self, mjcf_name: str, inline: str = "scene") -> str:
        """`file:line: path` of what the scene calls `mjcf_name` (what is known of it), for a message at run time;
        an inline scene's path starts with `inline`, where the composition has it."""
        path, line = self.places.get(mjcf_name, ((mjcf_name,) if mjcf_name else (), 0))
        if len(path) == 3:  # a named body: its name after its path
            path, called = path[:2], f" '{path[2]}'"
        else:
            called = ""
        dotted = ".".join(str(part) for part in (() if self.file else (inline,)) + path) + called
        return f"{self.file}{f':{line}' if line else ''}: {dotted}" if self.file else dotted


def _places(scene: Scene, line) -> dict[str, tuple[tuple, int]]:
    """Where a scene declares each body the engine may blame at run time; `line(path)` finds its line."""
    named = {f"bodies[{i}]": ("bodies", i) for i in range(len(scene.bodies))}
    named.update({f"handle_{h.name}": ("handles", i) for i, h in enumerate(scene.handles)})
    named["robot"] = ("robot",)
    called = {f"bodies[{i}]": b.name for i, b in enumerate(scene.bodies) if b.name}
    return {name: (path + ((called[name],) if name in called else ()), line(path)) for name, path in named.items()}


def find(name: str, folder: Path | None = None) -> Path | None:
    """The file a scene reference names: absolute; a shipped name; beside the composition (`folder`, or,
    at run time, the folder of the composition loaded: `hapticop.blocks.registry.beside_folders`). Never
    elsewhere on Python's search path: the run must read the file validation read."""
    path = Path(name)
    if path.is_absolute():
        return path if path.exists() else None
    if path.suffix == "" and (SHIPPED / f"{name}.yaml").is_file():
        return SHIPPED / f"{name}.yaml"
    folders = [folder] if folder is not None else [Path(p) for p in beside_folders()]
    for place in folders:
        candidate = place / path
        if candidate.is_file():
            return candidate
    return None


def load(ref: str | Scene, folder: Path | None = None, prefix: tuple = ()) -> tuple[Loaded | None, list[Diagnostic]]:
    """The scene `ref` names, checked; or None and the findings (paths under `prefix` for an inline one)."""
    if isinstance(ref, Scene):
        found = check(ref, prefix)
        if isinstance(ref.targets, str) and not found:
            ref, found = with_targets(ref, folder, Diagnostic("", "", prefix + ("targets",)))
        return (None if found else Loaded(to_mjcf(ref), ref, "", _places(ref, lambda path: 0))), found
    path = find(ref, folder)
    if path is None:
        return None, [Diagnostic("scene-file", f"no scene '{ref}': not a shipped scene "
                                 f"({', '.join(sorted(p.stem for p in SHIPPED.glob('*.yaml')))}) nor a file beside "
                                 "the composition", prefix, hint="a path relative to the composition's folder")]
    try:
        text = read_text(path, "a scene")
    except SourceError as error:
        return None, [error.diagnostic]
    if path.suffix.lower() == ".xml":
        found = _loads(text, str(path), ())
        return (None if found else Loaded(text, None, str(path))), found
    try:
        source = parse_text(text, str(path))
    except SourceError as error:
        return None, [error.diagnostic]
    try:
        scene = Scene.model_validate(source.tree)
    except ValidationError as error:
        return None, [source.place(d) for d in diagnostics_from(error, Scene)]
    found = [source.place(d) for d in check(scene, ())]
    if isinstance(scene.targets, str) and not found:
        scene, found = with_targets(scene, path.parent, source.place(Diagnostic("", "", ("targets",))))
    if found:
        return None, found
    places = _places(scene, lambda at: source.locate(at)[0] or 0)
    return Loaded(to_mjcf(scene, path.stem), scene, str(path), places), found


class TargetsFile(BaseModel):
    """A file of targets: what it is, and the targets."""

    model_config = ConfigDict(extra="forbid")
    doc: str = ""
    targets: tuple[Target, ...]


def with_targets(scene: Scene, folder: Path | None, named_at: Diagnostic) -> tuple[Scene, list[Diagnostic]]:
    """The scene with the targets of the file its `targets` names (a shipped name such as 'hallway', or a
    path beside the scene), or the findings located in that file (`named_at`: where the scene names it)."""
    name = str(scene.targets)
    shipped = SHIPPED / "targets" / f"{name}.yaml"
    path = shipped if Path(name).suffix == "" and shipped.is_file() else find(name, folder)
    if path is None:
        known = ", ".join(sorted(p.stem for p in (SHIPPED / "targets").glob("*.yaml")))
        return scene, [Diagnostic("scene-targets", f"no targets file '{name}': not a shipped one ({known}) nor a "
                                  "file beside the scene", named_at.path, file=named_at.file, line=named_at.line,
                                  column=named_at.column)]
    try:
        source = parse_text(read_text(path, "a targets file"), str(path))
        listed = TargetsFile.model_validate(source.tree)
    except SourceError as error:
        return scene, [error.diagnostic]
    except ValidationError as error:
        return scene, [source.place(d) for d in diagnostics_from(error, TargetsFile)]
    return scene.model_copy(update={"targets": listed.targets}), []


def check(scene: Scene, prefix: tuple) -> list[Diagnostic]:
    """What is wrong with a scene that its model alone cannot say."""
    found = []
    for kind in ("walls", "boxes", "cylinders", "bodies"):
        for i, item in enumerate(getattr(scene, kind)):
            if scene.material(item.material) is None:
                known = sorted({*scene.materials, *_shipped_materials()})
                found.append(Diagnostic("scene-material", f"unknown material '{item.material}'",
                                        prefix + (kind, i, "material"), hint=f"one of {', '.join(known)}, or "
                                        "define it under 'materials'"))
    floor = scene.floor.material
    if scene.material(floor) is None:
        found.append(Diagnostic("scene-material", f"unknown material '{floor}'", prefix + ("floor", "material")))
    for i, body in enumerate(scene.bodies):
        if body.mass_kg is None or body.mass_kg <= 0:
            found.append(Diagnostic("scene-mass", f"movable body '{body.name or i}' has no mass: a body that moves "
                                    "needs mass_kg > 0", prefix + ("bodies", i), hint="mass_kg: 5.0; or make it a "
                                    "static box under 'boxes'"))
        if body.shape == "box" and body.size_m is None:
            found.append(Diagnostic("scene-shape", "a movable box needs size_m", prefix + ("bodies", i)))
        if body.shape == "cylinder" and (body.radius_m is None or body.height_m is None):
            found.append(Diagnostic("scene-shape", "a movable cylinder needs radius_m and height_m",
                                    prefix + ("bodies", i)))
    seen: set[str] = set()
    for i, handle in enumerate(scene.handles):
        if handle.name in seen:
            found.append(Diagnostic("scene-handle", f"a second handle named '{handle.name}': its ports would be "
                                    "the first's", prefix + ("handles", i, "name"), hint="give each handle a name "
                                    "of its own"))
        seen.add(handle.name)
    if scene.hallway is not None:
        names = {mjcf for mjcf, _ in scene.static_names()} | {getattr(scene, kind)[i].name
                                                                for _, (kind, i) in scene.static_names()}
        for j, wall in enumerate(scene.hallway.end_wall):
            if wall not in names:
                known = ", ".join(sorted(n for n in names if n)) or "none"
                found.append(Diagnostic("scene-task", f"the hallway's end wall '{wall}' is no static geometry of "
                                        "the scene", prefix + ("hallway", "end_wall", j), expected=f"one of: {known}"))
    if found:
        return found
    xml = to_mjcf(scene)
    loading = _loads(xml, "", prefix)
    return loading or _overlaps(scene, xml, prefix)


def _shipped_materials() -> list[str]:
    from hapticop.sim.scene import MATERIALS

    return list(MATERIALS)


def _loads(xml: str, file: str, prefix: tuple) -> list[Diagnostic]:
    """MuJoCo's own word on the scene, as one line; nothing when it loads and has the robot."""
    from hapticop.sim.engine import Engine

    try:
        Engine(xml)
    except Exception as error:  # noqa: BLE001 - MuJoCo's errors are ValueError or its own: one finding
        message = " ".join(str(error).split())
        return [Diagnostic("scene-load", f"MuJoCo cannot load the scene: {message}", prefix, file=file)]
    return []


def _overlaps(scene: Scene, xml: str, prefix: tuple) -> list[Diagnostic]:
    """Static geometry overlapping other static geometry; the robot or a body starting inside anything."""
    import math

    import mujoco
    import numpy as np

    from hapticop.sim.engine import Engine

    engine = Engine(xml)
    m, d = engine.model, engine.data
    start = scene.robot.start
    engine.place_robot(np.array([start[0], start[1], math.radians(start[2])]))
    mujoco.mj_kinematics(m, d)
    paths = {name: path for name, path in scene.static_names()}
    geom = {name: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, name) for name in paths}
    names = list(paths)
    found = []
    for a in range(len(names)):
        for b in range(a + 1, len(names)):
            depth = mujoco.mj_geomDistance(m, d, geom[names[a]], geom[names[b]], 0.01, None)
            if depth < -OVERLAP_M:
                found.append(Diagnostic("scene-overlap", f"{_what(scene, paths[names[b]])} overlaps "
                                        f"{_what(scene, paths[names[a]])} by {-depth * 1000:.0f} mm",
                                        prefix + paths[names[b]], hint="static geometry may touch, not overlap"))
    movers = [("robot", engine.robot_geom, ("robot", "start"))] + [
        (f"body '{b.name or i}'", mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"bodies[{i}]"), ("bodies", i,
                                                                                                  "position_m"))
        for i, b in enumerate(scene.bodies)] + [
        (f"handle '{h.name}'", mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"handle_{h.name}"),
         ("handles", i, "origin_m")) for i, h in enumerate(scene.handles)]
    for what, g, path in movers:
        for name in names:
            depth = mujoco.mj_geomDistance(m, d, g, geom[name], 0.01, None)
            if depth < -OVERLAP_M:
                found.append(Diagnostic("scene-start-inside", f"the {what} starts inside "
                                        f"{_what(scene, paths[name])} ({-depth * 1000:.0f} mm deep)", prefix + path,
                                        hint="move it clear of the static geometry"))
    for what, g, path in movers[1:]:
        depth = mujoco.mj_geomDistance(m, d, g, engine.robot_geom, 0.01, None)
        if depth < -OVERLAP_M:
            found.append(Diagnostic("scene-start-inside", f"the {what} starts inside the robot "
                                    f"({-depth * 1000:.0f} mm deep)", prefix + path, hint="move it clear of the "
                                    "robot's start"))
    return found


def _what(scene: Scene, path: tuple) -> str:
    kind, i = path
    name = getattr(scene, kind)[i].name
    return f"{kind}[{i}]" + (f" '{name}'" if name else "")
