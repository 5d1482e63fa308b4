"""Turning pydantic's validation errors into diagnostics a person can act on.

pydantic knows what was wrong; this module adds where (the YAML path, with union tags
removed: a parameter set chosen by its `kind` is not a key of its own), what was expected,
and a hint such as the key that was probably meant.
"""

from __future__ import annotations

import dataclasses
import difflib
import re
import types
import typing
from typing import Any

from pydantic import BaseModel, ValidationError

from hapticop.composition.diagnostics import Diagnostic, Path


def diagnostics_from(error: ValidationError, model: type[BaseModel], prefix: Path = ()) -> list[Diagnostic]:
    found = []
    for item in error.errors(include_url=False):
        loc = _clean_loc(item["loc"], model)
        found.append(_one(item, loc, model, prefix))
    return found


_TAG = re.compile(r"^([A-Za-z_][\w-]*\[.*\]|\[key\])$")


def _clean_loc(loc: tuple, model: type[BaseModel]) -> Path:
    """Drop the tags pydantic inserts for unions and validators (they are not YAML keys)."""
    cleaned: list = []
    annotation: Any = model
    for index, part in enumerate(loc):
        is_tag = isinstance(part, str) and bool(_TAG.match(part))
        is_policy_tag = part in ("latest", "queue") and cleaned and cleaned[-1] == "policy" and index < len(loc) - 1
        if is_tag or is_policy_tag:
            continue
        kind = _kind_member(annotation, part) if index < len(loc) - 1 else None
        if kind is not None:  # a discriminated union's tag: the member its `kind` names
            annotation = kind
            continue
        cleaned.append(part)
        annotation = _step(annotation, part)
    return tuple(cleaned)


def _kind_member(annotation: Any, part: Any) -> type | None:
    """The member of a union of models that `part` names by its `kind` field (pydantic's tag), if any."""
    models = _models_in(annotation)
    if len(models) < 2 or any(part in _fields(m) for m in models):
        return None
    for m in models:
        if part in _kinds_of(m, "kind"):
            return m
    return None


def _one(item: dict, loc: Path, model: type[BaseModel], prefix: Path) -> Diagnostic:
    kind = item["type"]
    value = item.get("input")
    path = prefix + loc
    name = str(item["loc"][-1]) if item["loc"] else "<document>"
    if kind in ("extra_forbidden", "unexpected_keyword_argument"):
        allowed = allowed_keys(model, tuple(item["loc"][:-1]))
        close = difflib.get_close_matches(name, allowed, n=1, cutoff=0.6)
        hint = f"did you mean '{close[0]}'?" if close else ""
        return Diagnostic(
            rule="unknown-key",
            message=f"unknown key '{name}'",
            path=path,
            expected=f"one of: {', '.join(allowed)}" if allowed else "",
            hint=hint,
        )
    if kind == "missing":
        return Diagnostic(rule="missing-key", message=f"missing required key '{name}'", path=path)
    if kind == "literal_error":
        expected = item.get("ctx", {}).get("expected", "")
        return Diagnostic(rule="bad-value", message=f"{value!r} is not allowed", path=path, expected=expected)
    if kind == "union_tag_not_found":
        key = item.get("ctx", {}).get("discriminator", "").strip("'")
        kinds = [value for m in _models_in(_annotation_at(model, item["loc"])) for value in _kinds_of(m, key)]
        return Diagnostic(rule="missing-key", message=f"missing required key '{key}'", path=path,
                          expected=", ".join(repr(k) for k in kinds))
    if kind == "union_tag_invalid":
        expected = item.get("ctx", {}).get("expected_tags", "")
        return Diagnostic(rule="bad-value", message=f"unknown kind {item['ctx'].get('tag')!r}", path=path,
                          expected=expected)
    if kind == "predicate_failed":
        said = re.search(r"Predicate '?(\w+)'? failed", item["msg"])
        must = f"must be {said.group(1)}" if said else "is not allowed"
        return Diagnostic(rule="bad-value", message=f"'{name}' {must} (got {value!r})", path=path)
    if kind == "string_pattern_mismatch":
        pattern = item.get("ctx", {}).get("pattern", "")
        return Diagnostic(
            rule="bad-name",
            message=f"{value!r} is not a valid {_what_pattern(pattern)}",
            path=path,
            expected=_pattern_expected(pattern),
        )
    bounds = {"greater_than_equal": ("at least", "ge"), "less_than_equal": ("at most", "le"),
              "greater_than": ("more than", "gt"), "less_than": ("less than", "lt")}
    if kind in bounds:
        words, key = bounds[kind]
        limit = item.get("ctx", {}).get(key)
        return Diagnostic(rule="bad-value", message=f"'{name}' must be {words} {limit} (got {value!r})",
                          path=path)
    if kind in _TYPES:
        return _wrong_type(_TYPES[kind], name, value, path)
    rule = "bad-value"
    custom = {"priority_range": "priority-range", "duration": "bad-duration", "duration_unit": "bad-duration",
              "version": "bad-version", "stream_one_writer": "stream-writers"}
    rule = custom.get(kind, rule)
    message = item["msg"]
    if kind not in custom and value is not None and not isinstance(value, (dict, list)):
        message = f"{message} (got {value!r})"
    return Diagnostic(rule=rule, message=message, path=path)


# pydantic's error types for a value of the wrong type, and what the field takes instead
_TYPES = {
    "float_parsing": "a number", "float_type": "a number",
    "int_parsing": "a whole number", "int_type": "a whole number", "int_from_float": "a whole number",
    "bool_parsing": "true or false", "bool_type": "true or false", "string_type": "text",
    "list_type": "a list such as [1.0, 2.0]", "tuple_type": "a list such as [1.0, 2.0]",
    "dict_type": "a mapping of keys to values", "model_type": "a mapping of keys to values",
    "model_attributes_type": "a mapping of keys to values", "dataclass_type": "a mapping of keys to values",
}

# the unit a parameter's name ends with (units live in field names: `kp_n_per_m`, `timeout_s`)
_NAME_UNITS = (
    ("_ns_per_m", "N·s/m"), ("_n_per_m", "N/m"), ("_n_per_s", "N/s"), ("_m_per_n", "m/N"),
    ("_nm_per_a", "N·m/A"), ("_a_per_rad_s", "A per rad/s"), ("_rad_per_s", "rad/s"), ("_m_per_s", "m/s"),
    ("_rad_s", "rad/s"), ("_mps", "m/s"), ("_hz", "Hz"), ("_deg", "degrees"), ("_rad", "rad"),
    ("_per_s", "1/s"), ("_per_m", "1/m"), ("_kg", "kg"), ("_nm", "N·m"), ("_ms", "ms"), ("_s", "s"),
    ("_m", "m"), ("_n", "N"), ("_a", "A"),
)


def unit_of(name: str) -> str:
    """The unit a field's name states, such as 'N/m' for `kp_n_per_m`; '' when it names none."""
    return next((unit for suffix, unit in sorted(_NAME_UNITS, key=lambda pair: -len(pair[0]))
                 if name.endswith(suffix)), "")


def _wrong_type(expected: str, name: str, value: Any, path: Path) -> Diagnostic:
    """A value of the wrong type: what the field takes, in which unit, and how to write it."""
    unit = unit_of(name) if "number" in expected else ""
    takes = f"{expected} in {unit}" if unit else expected
    got = "" if isinstance(value, (dict, list)) else f" (got {value!r})"
    hint = ""
    if unit:
        hint = f"write the number alone, such as 1.5: the unit ({unit}) is in the key's name"
    elif isinstance(value, str) and "number" in expected:
        hint = "write the number without quotes or a unit"
    elif expected == "true or false":
        hint = "write true or false, without quotes"
    return Diagnostic(rule="bad-value", message=f"'{name}' takes {takes}{got}", path=path, expected=takes, hint=hint)


def _what_pattern(pattern: str) -> str:
    if "\\." in pattern and "(" in pattern:
        return "flag name"
    if "\\." in pattern:
        return "port reference"
    if ":" in pattern:
        return "block type"
    return "name"


def _pattern_expected(pattern: str) -> str:
    return {
        "flag name": "a dotted flag name such as 'falcon.lcsm.running'",
        "port reference": "'activity.port' in lower_snake_case",
        "block type": "a built-in block name or 'package.module:ClassName'",
    }.get(_what_pattern(pattern), "letters, digits and '_', starting with a letter "
          "(lower_snake_case for threads, activities, streams, nets)")


def allowed_keys(model: type[BaseModel], path: Path) -> list[str]:
    """The keys the model accepts at `path`, pydantic's location with its tags (for 'did you mean' hints)."""
    annotation = _annotation_at(model, path)
    if annotation is None:
        return []
    keys: list[str] = []
    for m in _models_in(annotation):
        for key in _fields(m):
            if key not in keys:
                keys.append(key)
    return keys


def _annotation_at(model: type[BaseModel], path: Path) -> Any:
    """The type the model expects at pydantic's location `path` (tags and all); None if unknown."""
    annotation: Any = model
    for part in path:
        if isinstance(part, str) and _TAG.match(part):
            continue
        annotation = _kind_member(annotation, part) or _step(annotation, part)
        if annotation is None:
            return None
    return annotation


def _kinds_of(model: type, key: str) -> tuple:
    """The values a model's literal `key` field may take (a union member's tags)."""
    annotation = _unwrap(_fields(model).get(key))
    return typing.get_args(annotation) if typing.get_origin(annotation) is typing.Literal else ()


def _fields(model: type) -> dict[str, Any]:
    """Key -> annotation of a pydantic model or a dataclass (block parameters may nest either)."""
    if isinstance(model, type) and issubclass(model, BaseModel):
        return {info.alias or name: info.annotation for name, info in model.model_fields.items()}
    hints = typing.get_type_hints(model, include_extras=True)  # the fields' types, not their source text
    return {f.name: hints.get(f.name, f.type) for f in dataclasses.fields(model)}


def _models_in(annotation: Any) -> list[type[BaseModel]]:
    annotation = _unwrap(annotation)
    if isinstance(annotation, type) and (issubclass(annotation, BaseModel) or dataclasses.is_dataclass(annotation)):
        return [annotation]
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        return [m for arg in typing.get_args(annotation) for m in _models_in(arg)]
    return []


def _unwrap(annotation: Any) -> Any:
    while typing.get_origin(annotation) is typing.Annotated:
        annotation = typing.get_args(annotation)[0]
    return annotation


def _step(annotation: Any, part: Any) -> Any:
    annotation = _unwrap(annotation)
    for model in _models_in(annotation):
        found = _fields(model).get(part)
        if found is not None:
            return found
    origin = typing.get_origin(annotation)
    if origin is dict:
        return typing.get_args(annotation)[1]
    if origin is list:
        return typing.get_args(annotation)[0]
    if origin in (typing.Union, types.UnionType):
        for arg in typing.get_args(annotation):
            stepped = _step(arg, part)
            if stepped is not None:
                return stepped
    return None
