"""`hapticop blocks`: the author's reference, built from the blocks' own declarations."""

import json
import sys
import textwrap

import pytest
from typer.testing import CliRunner

from hapticop.blocks import registry
from hapticop.blocks.catalogue import catalogue, to_markdown
from hapticop.blocks.registry import BUILTIN
from hapticop.cli import app

from .conftest import ROOT

runner = CliRunner()


def test_docs_blocks_md_is_the_current_catalogue():
    current = (ROOT / "docs" / "blocks.md").read_text()
    assert current == to_markdown(catalogue(list(BUILTIN))), "run `hapticop blocks --markdown > docs/blocks.md`"


def test_every_built_in_block_is_described_in_full():
    for entry in catalogue(list(BUILTIN)):
        assert not entry.error, entry.name
        assert entry.summary and "reusable unit of computation" not in entry.summary, entry.name
        for port in [*entry.inputs.values(), *entry.outputs.values()]:
            assert port["unit"], (entry.name, port)
        for parameter in entry.parameters:
            assert parameter.description, (entry.name, parameter.name)
            assert parameter.live in ("retunes live", "capability configuration", "resource configuration")


def test_one_block_in_detail_names_ports_units_defaults_and_what_a_patch_does():
    result = runner.invoke(app, ["blocks", "haptic_controller"])
    assert result.exit_code == 0, result.output
    assert "input handle_position: float64[3] [m]" in result.output
    assert "param driving.k1_per_s: number = 28.0 [1/s] (retunes live)" in result.output
    assert "param scan_points: integer >= 2 <= 10000 = 811 (resource configuration)" in result.output
    assert "reads flag resources_ready" in result.output


def test_json_lists_every_built_in_block():
    result = runner.invoke(app, ["blocks", "--json"])
    assert result.exit_code == 0, result.output
    entries = {entry["name"]: entry for entry in json.loads(result.output)}
    assert set(BUILTIN) <= set(entries)
    assert entries["falcon"]["outputs"]["position"] == {"dtype": "float64", "shape": [3], "unit": "m",
                                                        "doc": entries["falcon"]["outputs"]["position"]["doc"],
                                                        "required": True, "range": None}
    assert entries["ropod_controller"]["inputs"]["velocity_setpoint"]["range"] == [-10.0, 10.0]


def test_a_block_by_import_path_and_an_unknown_one():
    result = runner.invoke(app, ["blocks", "tests.blocks:Noise"])
    assert result.exit_code == 0 and "output sample" in result.output
    result = runner.invoke(app, ["blocks", "haptic_controler"])
    assert result.exit_code == 1
    assert "unknown block type 'haptic_controler' (did you mean 'haptic_controller'?)" in result.output
    assert "Traceback" not in result.output


@pytest.fixture
def installed_package(tmp_path, monkeypatch):
    """A package that gives its block a short name through the `hapticop.blocks` entry points."""
    (tmp_path / "springs.py").write_text(textwrap.dedent('''
        """A third party's blocks."""
        from hapticop.blocks.base import Block
        from hapticop.blocks.interface import Port

        class Spring(Block):
            """A spring to the origin, from a package of its own."""
            outputs = {"force": Port("float64", (3,), "N")}
    '''))
    info = tmp_path / "springs-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: springs\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text("[hapticop.blocks]\nspring = springs:Spring\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    registry.installed.cache_clear()
    yield
    registry.installed.cache_clear()
    sys.modules.pop("springs", None)


def test_an_installed_package_names_its_blocks(installed_package):
    assert registry.resolve("spring").__name__ == "Spring"
    result = runner.invoke(app, ["blocks"])
    assert result.exit_code == 0 and "spring" in result.output and "from a package of its own" in result.output
    (entry,) = catalogue(["spring"])
    assert entry.origin == "installed" and entry.outputs["force"]["unit"] == "N"


def test_nested_parameter_sets_are_shown_with_their_units_and_what_chooses_them():
    """A choice told apart by `kind` (the workspace's sphere, the force models), an optional set (the
    governor) and a list of sets: each key listed under the parameter holding it, indented."""
    result = runner.invoke(app, ["blocks", "workspace_limit", "haptic_controller", "zenoh_bridge", "scripted_hand"])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert "    param limit.radius_m (kind 'sphere'): number > 0 = 0.04 [m] (retunes live) - Its radius." in lines
    assert any(line.startswith("    param limit.half_size_m (kind 'box'): [number > 0, number > 0, number > 0]")
               and "[m]" in line for line in lines)
    assert any(line.startswith("    param force_model.fz_max_n (kind 'braking_field'): number >= 0 = 6.0 [N]")
               for line in lines)
    assert any(line.startswith("    param force_model.k3_n_per_m (kind 'thesis' or 'thesis_corrected')")
               for line in lines)
    assert any(line.startswith("    param governor.brake_decel_mps2 (when given): number > 0 = 0.5 [m/s²]")
               for line in lines)
    assert any(line.startswith("    param emulate.delay_s (when given): number >= 0 = 0.0 [s]") for line in lines)
    assert any(line.startswith("    param script[].t_s: number >= 0.0") and "[s]" in line for line in lines)
    assert any(line.startswith("  param centring: CentringParams (retunes live) - ") for line in lines)
    assert "    param centring.kp_n_per_m: number >= 0 = 55.0 [N/m] (retunes live) - Spring to the origin, N/m." \
        in lines
    markdown = to_markdown(catalogue(["workspace_limit"]))
    assert "| &nbsp;&nbsp;&nbsp;&nbsp;`limit.radius_m` (kind 'sphere') | number > 0 | `0.04` | m |" in markdown
