"""The published JSON Schema is current, valid, and accepts every system file."""

import json

import jsonschema
import pytest
from ruamel.yaml import YAML

from hapticop.composition.layers import resolve
from hapticop.composition.schema import SCHEMA_FILE, composition_schema, schema_text
from hapticop.composition.yamlsource import plain, read_file

from .conftest import CORPUS, SYSTEMS


def test_schema_file_is_current():
    assert SCHEMA_FILE.read_text() == schema_text(), "run `hapticop schema --write`"


def test_schema_is_valid_draft_2020_12():
    jsonschema.Draft202012Validator.check_schema(composition_schema())


@pytest.mark.parametrize("path", sorted(SYSTEMS.glob("*.yaml")) + sorted((CORPUS / "valid").glob("*.yaml")),
                         ids=lambda p: p.name)
def test_system_files_satisfy_the_schema(path):
    merged = plain(resolve(read_file(path)).tree)  # a file that extends another is checked merged
    document = json.loads(json.dumps(merged))
    # JSON Schema object keys are strings: schedule IDs arrive as "0", "1".
    jsonschema.validate(document, composition_schema())


def test_system_files_reference_the_schema():
    for path in SYSTEMS.glob("*.yaml"):
        if "extends" in YAML(typ="safe").load(path.read_text()):
            continue  # only the differences from its base: the schema's required fields are not there
        assert path.read_text().startswith("# yaml-language-server: $schema=../schemas/composition.schema.json")


def test_schema_completes_block_params():
    schema = composition_schema()
    conditions = schema["$defs"]["Activity"]["allOf"]
    falcon = next(c for c in conditions if c["if"]["properties"]["block"]["const"] == "falcon")
    assert falcon["then"]["properties"]["params"]["$ref"] == "#/$defs/FalconParams"
    with pytest.raises(jsonschema.ValidationError, match="'serial' is not one of"):
        jsonschema.validate(
            {"version": 1, "threads": {"main": {"period": "1ms", "schedules": {"0": ["f"]}}},
             "activities": {"f": {"block": "falcon", "params": {"driver": "serial"}}}},
            schema,
        )
