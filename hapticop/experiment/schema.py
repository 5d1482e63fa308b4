"""The JSON Schema of experiment files (schemas/experiment.schema.json), from the pydantic model: editors
complete and check an experiment file as they do a composition."""

from __future__ import annotations

import json
from pathlib import Path

from hapticop.experiment.description import Experiment

SCHEMA_FILE = Path(__file__).resolve().parents[2] / "schemas" / "experiment.schema.json"
SCHEMA_ID = "https://hapticop.invalid/schemas/experiment.schema.json"


def experiment_schema() -> dict:
    schema = Experiment.model_json_schema()
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "$id": SCHEMA_ID,
            "title": "hapticop experiment", **{k: v for k, v in schema.items() if k != "title"}}


def schema_text() -> str:
    return json.dumps(experiment_schema(), indent=2) + "\n"
