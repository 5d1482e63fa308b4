"""The JSON Schema of composition files, generated from the models, for editors and CI.

Each built-in block's parameter model is included, selected by the activity's `block`
with an if/then, so an editor completes `params` for the block being written.
"""

from __future__ import annotations

import json
from pathlib import Path

from pydantic.json_schema import models_json_schema

from hapticop.blocks.registry import BUILTIN, resolve
from hapticop.composition.description import Composition

SCHEMA_FILE = Path(__file__).resolve().parents[2] / "schemas" / "composition.schema.json"
SCHEMA_ID = "https://hapticop.invalid/schemas/composition.schema.json"


def composition_schema() -> dict:
    blocks = {name: resolve(name) for name in sorted(BUILTIN)}
    models = [(Composition, "validation")] + [(cls.Params, "validation") for cls in blocks.values()]
    keys, schema = models_json_schema(models, ref_template="#/$defs/{model}")
    defs = schema["$defs"]
    root = defs.pop("Composition")
    conditions = []
    for name, cls in blocks.items():
        ref = keys[(cls.Params, "validation")]["$ref"]
        conditions.append(
            {
                "if": {"properties": {"block": {"const": name}}, "required": ["block"]},
                "then": {"properties": {"params": {"$ref": ref}}},
            }
        )
    defs["Activity"]["allOf"] = conditions
    _admit_shorthands(defs)
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": SCHEMA_ID,
        "title": "hapticop composition",
        **root,
        "$defs": defs,
    }


def schema_text() -> str:
    return json.dumps(composition_schema(), indent=2, sort_keys=False) + "\n"


def _admit_shorthands(defs: dict) -> None:
    """The models accept a few short forms before validation; let editors accept them too."""
    stream = defs["Stream"]["properties"]
    stream["to"] = {"anyOf": [stream["to"]["items"], stream["to"]], "description": stream["to"]["description"]}
    policy = stream["policy"]
    stream["policy"] = {"anyOf": [{"enum": ["latest", "queue"]}, {k: v for k, v in policy.items() if k != "title"}]}
    for side in ("in", "out"):
        arcs = defs["Transition"]["properties"][side]
        names = {"type": "array", "items": arcs["propertyNames"] if "propertyNames" in arcs else {"type": "string"}}
        defs["Transition"]["properties"][side] = {"anyOf": [arcs, names], "description": arcs.get("description", "")}
    schedules = defs["Thread"]["properties"]["schedules"]
    schedules["propertyNames"] = {"pattern": "^[0-9]+$"}
