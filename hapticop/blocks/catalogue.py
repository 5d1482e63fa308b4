"""Every block an author can name, with what it declares: the reference `hapticop blocks` prints.

Built from the blocks' own declarations (ports, flags, rate, parameter models, which
parameters retune live), so the catalogue cannot drift from the code. Blocks whose ports
depend on their parameters are described with their defaults.
"""

from __future__ import annotations

import inspect
from dataclasses import asdict, dataclass, field
from typing import Any

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Port
from hapticop.blocks.registry import BUILTIN, UnknownBlock, installed, resolve

# Units by the suffix of a parameter's name (the project names SI quantities with their unit).
_UNITS = [("_n_per_mps", "N·s/m"), ("_n_per_rad_s", "N·s/rad"), ("_n_per_m", "N/m"), ("_ns_per_m", "N·s/m"),
          ("_rad_per_s_m", "rad/(s·m)"), ("_per_s", "1/s"),
          ("_rad_s", "rad/s"),
          ("_mps2", "m/s²"), ("_mps", "m/s"), ("_nm_per_a", "N·m/A"), ("_n_per_s", "N/s"), ("_n", "N"),
          ("_m", "m"), ("_s", "s"), ("_ms", "ms"), ("_hz", "Hz"), ("_fhz", "Hz"), ("_deg", "°"), ("_rad", "rad"),
          ("_a", "A"), ("_kg", "kg")]


@dataclass
class ParameterEntry:
    name: str  # dotted for nested parameter sets: driving.k1_per_s
    type: str
    default: Any
    unit: str
    description: str
    live: str  # "retunes live", "capability configuration", "resource configuration"
    variant: str = ""  # for a parameter inside one of a choice's models: which (kind 'sphere', when given)
    depth: int = 0  # how deep in nested parameter sets (0: a key of `params` itself)


@dataclass
class BlockEntry:
    name: str  # what a composition's `block:` says
    target: str  # module:Class
    origin: str  # built-in, installed (entry point) or import path
    summary: str
    inputs: dict[str, dict] = field(default_factory=dict)
    outputs: dict[str, dict] = field(default_factory=dict)
    flags_read: dict[str, str] = field(default_factory=dict)
    flags_written: dict[str, str] = field(default_factory=dict)
    rate: str = "any"
    needs: dict[str, str] = field(default_factory=dict)
    provides: list[str] = field(default_factory=list)
    parameters: list[ParameterEntry] = field(default_factory=list)
    error: str = ""  # why the block could not be described (an import that failed)

    def to_json(self) -> dict:
        return asdict(self)


def catalogue(names: list[str] | None = None) -> list[BlockEntry]:
    """Built-in and installed blocks (or just `names`, which may be import paths), described."""
    sources = {**{n: ("built-in", t) for n, t in BUILTIN.items()},
               **{n: ("installed", t) for n, t in installed().items() if n not in BUILTIN}}
    wanted = names if names else list(sources)
    return [describe(name, *sources.get(name, ("import path", name))) for name in wanted]


def describe(name: str, origin: str, target: str) -> BlockEntry:
    entry = BlockEntry(name, target, origin, "")
    try:
        cls = resolve(name)
    except UnknownBlock as error:
        entry.error = f"{error.reason}" + (f" ({error.hint})" if error.hint else "")
        return entry
    assert cls is not None  # resolve imports unless told not to
    entry.summary = _summary(cls)
    try:
        params = cls.Params()
    except ValueError:  # a default that needs a setting (the Falcon's firmware path): ports by defaults
        params = cls.Params.model_construct()
    iface = cls.declare(params)
    entry.inputs = {n: _port(p) for n, p in iface.inputs.items()}
    entry.outputs = {n: _port(p) for n, p in iface.outputs.items()}
    entry.flags_read, entry.flags_written = dict(iface.flags_read), dict(iface.flags_written)
    entry.rate = iface.rate.describe() if iface.rate else "any"
    entry.needs = dict(cls.needs)
    entry.provides = sorted(cls.provides)
    entry.parameters = _parameters(cls, params.model_dump(mode="json"))
    return entry


def _summary(cls: type[Block]) -> str:
    doc = inspect.getdoc(cls)
    if not doc or doc == inspect.getdoc(Block):
        doc = inspect.getdoc(inspect.getmodule(cls)) or ""
    return doc.strip().split("\n\n")[0].replace("\n", " ")


def _port(port: Port) -> dict:
    return {"dtype": port.dtype, "shape": list(port.shape), "unit": port.unit, "doc": port.doc,
            "required": port.required, "range": list(port.range) if port.range is not None else None}


def _range_text(port: dict) -> str:
    """A port's declared range, as a reader refuses samples outside it."""
    bounds = port.get("range")
    return f" (range [{bounds[0]:g}, {bounds[1]:g}]: a sample outside it is refused)" if bounds else ""


def _live(cls: type[Block], top: str) -> str:
    if top in cls.running_params:
        return "retunes live"
    if top in cls.capability_params:
        return "capability configuration"
    return "resource configuration"


def _parameters(cls: type[Block], defaults: dict) -> list[ParameterEntry]:
    """One entry per leaf parameter, read off the parameter model's JSON Schema: it carries the
    nested libraries' parameter sets with their docstrings, defaults and bounds."""
    schema = cls.Params.model_json_schema()
    defs = schema.get("$defs", {})
    found: list[ParameterEntry] = []

    def deref(prop: dict) -> dict:
        while True:
            if "$ref" in prop:
                prop = defs[prop["$ref"].rsplit("/", 1)[-1]]
            elif len(prop.get("allOf", ())) == 1:
                prop = prop["allOf"][0]
            else:
                return prop

    def walk(properties: dict, prefix: str, top: str, variant: str, depth: int) -> None:
        for name, prop in properties.items():
            if variant.startswith("kind") and name == "kind":
                continue  # the variant's heading says it
            dotted, root = f"{prefix}{name}", top or name
            target = deref(prop)
            description = " ".join((prop.get("description") or target.get("description", "")).split())
            if "properties" in target:  # a nested parameter set: its heading, then its own
                found.append(ParameterEntry(dotted, target.get("title", "parameters"), "", "", description,
                                            _live(cls, root), variant, depth))
                walk(target["properties"], f"{dotted}.", root, variant, depth + 1)
                continue
            # inside one of a choice's models, or a list's or mapping's, the defaults at hand are not this
            # model's: the schema's
            keyed = ".NAME." in dotted or "[]." in dotted
            default = prop.get("default", "(required)") if variant or keyed else _default_at(defaults, dotted)
            found.append(ParameterEntry(dotted, _type_name(prop, deref), default, unit_of(name), description,
                                        _live(cls, root), variant, depth))
            for label, model, nested in _nested_models(target, deref):
                walk(model["properties"], f"{dotted}{nested}", root, label, depth + 1)

    walk(schema.get("properties", {}), "", "", "", 0)
    return found


def _nested_models(prop: dict, deref) -> list[tuple[str, dict, str]]:
    """The parameter sets inside a parameter that is not one itself, with what chooses each and
    how their keys are reached: a choice told apart by `kind` (the workspace's box or sphere, the
    force models), an optional set (the governor: null or its parameters), a list or mapping of sets."""
    options = [deref(option) for option in prop.get("oneOf") or prop.get("anyOf") or ()]
    models = [option for option in options if "properties" in option]
    if models:
        nullable = len(models) < len(options)
        return [(_variant_label(model, nullable), model, ".") for model in models]
    items = deref(prop.get("items", {})) if prop.get("type") == "array" else {}
    if "properties" in items:
        return [("", items, "[].")]
    values = prop.get("additionalProperties")
    values = deref(values) if isinstance(values, dict) else {}
    if "properties" in values:
        return [("", values, ".NAME.")]
    return []


def _variant_label(model: dict, nullable: bool) -> str:
    kind = model["properties"].get("kind", {})
    kinds = [kind["const"]] if "const" in kind else kind.get("enum", [])
    if kinds:
        return "kind " + " or ".join(repr(k) for k in kinds)
    return "when given" if nullable else ""


def _default_at(defaults: dict, dotted: str) -> Any:
    """The default of a dotted parameter; a model chosen by `kind` is shown by its kind."""
    value: Any = defaults
    for part in dotted.split("."):
        if not isinstance(value, dict) or part not in value:
            return "(required)"
        value = value[part]
    if isinstance(value, dict) and "kind" in value:
        return f"kind {value['kind']} with its defaults"
    return value


def _type_name(prop: dict, deref) -> str:
    """A property's type in a few words: int, number >= 0, one of 'a', 'b', a union's variants."""
    prop = deref(prop)
    if "enum" in prop:
        return "one of " + ", ".join(repr(v) for v in prop["enum"])
    if "const" in prop:
        return repr(prop["const"])
    for key in ("anyOf", "oneOf"):
        if key in prop:
            return " or ".join(_type_name(option, deref) for option in prop[key])
    if "properties" in prop:
        label = _variant_label(prop, False)
        return f"{prop.get('title', 'object')}" + (f" ({label})" if label else "")
    kind = prop.get("type", "any")
    if kind == "array" and "prefixItems" in prop:
        return f"[{', '.join(_type_name(item, deref) for item in prop['prefixItems'])}]"
    if kind == "array":
        return f"list of {_type_name(prop.get('items', {}), deref)}"
    if kind == "object" and isinstance(prop.get("additionalProperties"), dict):
        return f"mapping of names to {_type_name(prop['additionalProperties'], deref)}"
    bounds = [f"{word} {prop[key]}" for key, word in (("minimum", ">="), ("exclusiveMinimum", ">"),
                                                      ("maximum", "<="), ("exclusiveMaximum", "<")) if key in prop]
    return " ".join([kind, *bounds])


def unit_of(name: str) -> str:
    """A parameter's unit, read off its name's suffix (`delay_s`: s); '' when it has none."""
    for suffix, unit in _UNITS:
        if name.endswith(suffix):
            return unit
    return ""


def to_markdown(entries: list[BlockEntry]) -> str:
    """The catalogue as the reference page docs/blocks.md."""
    lines = ["# Block catalogue", "",
             "Every built-in block, as `hapticop blocks` describes it from the blocks' own declarations",
             "(regenerate with `hapticop blocks --markdown > docs/blocks.md`; a test keeps it current).",
             "Ports are described for the block's default parameters; *live* says what a patch of that",
             "parameter does to a running activity: it retunes between two cycles, or takes the activity",
             "through capability or resource configuration. Nested parameter sets are indented under the",
             "key that holds them; inside a choice (`kind`) or an optional set, a parameter says which",
             "it belongs to; `[]` is each item of a list, `NAME` each entry of a mapping.", ""]
    for entry in entries:
        lines += [f"## `{entry.name}`", "", f"`{entry.target}` ({entry.origin}). {entry.summary}", ""]
        if entry.error:
            lines += [f"Cannot be described: {entry.error}", ""]
            continue
        lines.append(f"Rate: {entry.rate}.")
        if entry.needs:
            lines.append("Needs: " + ", ".join(f"`{p}` names an activity providing {w}" for p, w in entry.needs.items())
                         + ".")
        if entry.provides:
            lines.append("Provides: " + ", ".join(entry.provides) + ".")
        lines.append("")
        for title, ports in (("Inputs", entry.inputs), ("Outputs", entry.outputs)):
            if ports:
                lines += [f"{title}:", "", "| port | dtype | shape | unit | |", "|---|---|---|---|---|"]
                lines += [f"| `{n}` | {p['dtype']} | {tuple(p['shape'])} | {p['unit']} | {p['doc']}"
                          f"{'' if p['required'] else ' (optional)'}{_range_text(p)} |" for n, p in ports.items()]
                lines.append("")
        for title, flags in (("Flags read", entry.flags_read), ("Flags written", entry.flags_written)):
            if flags:
                lines += [f"{title}: " + "; ".join(f"`{n}` ({d})" for n, d in flags.items()) + ".", ""]
        if entry.parameters:
            lines += ["| parameter | type | default | unit | live | |", "|---|---|---|---|---|---|"]
            lines += [f"| {'&nbsp;' * 4 * p.depth}`{p.name}`{f' ({p.variant})' if p.variant else ''} | "
                      f"{p.type.replace('|', '∣')} | `{p.default}` | {p.unit} | {p.live} | "
                      f"{p.description.replace('|', '∣')} |" for p in entry.parameters]
            lines.append("")
    return "\n".join(lines).rstrip() + "\n"
