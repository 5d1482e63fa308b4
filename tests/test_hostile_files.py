"""Hostile files given to `hapticop validate`: refused with one located line, never a hang or a traceback.

Each case is a file made here: an alias bomb in each place a value is read after parsing, a
FIFO, a character device, a symlink loop, a NUL byte in an `extends:` name, bytes that are not
UTF-8. The answer must be exit 1 or 2 and a line naming the file.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
from typer.testing import CliRunner

from hapticop.cli import app

from .conftest import ROOT

runner = CliRunner()

pytestmark = pytest.mark.timeout(20)


def bomb(levels: int = 9, width: int = 9) -> str:
    """A flow sequence of a few hundred bytes whose aliases name width**levels values."""
    items = [f"&a0 [{', '.join(['lol'] * width)}]"]
    items += [f"&a{n} [{', '.join([f'*a{n - 1}'] * width)}]" for n in range(1, levels)]
    return f"[{', '.join(items)}]"


MINIMAL = """version: 1
threads:
  main:
    period: {period}
    deploy: main
    schedules:
      0: [mediator, counter, echo]
activities:
  mediator:
    block: mediator
  echo:
    block: echo
    params: {{dtype: {dtype}}}
  counter:
    block: counter
streams:
  s: {{from: counter.count, to: [echo.input], max_age: {max_age}}}
{extra}"""

PLACES = {
    "duration": dict(period=bomb(), dtype="int64", extra=""),
    "literal-parameter": dict(period="1ms", dtype=bomb(), extra=""),
    "stream-max-age": dict(period="1ms", dtype="int64", max_age=bomb(), extra=""),
    "scripted-patch-at": dict(period="1ms", dtype="int64",
                              extra=f"patches:\n  p:\n    at: {bomb()}\n    patch: {{name: x}}\n"),
    "json-patch-value": dict(
        period="1ms", dtype="int64",
        extra=f"patches:\n  p:\n    at: 1s\n    patch: [{{op: add, path: /doc, value: {bomb()}}}]\n"),
}


for place in PLACES.values():
    place.setdefault("max_age", "1s")


def refused(result, file) -> str:
    """The located line naming `file`; checks the exit status and the absence of a crash."""
    assert result.exit_code in (1, 2), result.output
    assert "Traceback" not in result.output and "internal error" not in result.output, result.output
    lines = [line for line in result.output.splitlines() if line.startswith(f"{file}:") and "error:" in line]
    assert lines, result.output
    return lines[0]


@pytest.mark.parametrize("place", sorted(PLACES))
def test_alias_bomb_is_refused_wherever_it_stands(tmp_path, place):
    file = tmp_path / f"{place}.yaml"
    file.write_text(MINIMAL.format(**PLACES[place]))
    line = refused(runner.invoke(app, ["validate", str(file)]), file)
    assert "aliases expand" in line


def test_deep_nesting_is_refused(tmp_path):
    file = tmp_path / "deep.yaml"
    file.write_text(MINIMAL.format(period="1ms", dtype="[" * 200 + "]" * 200, max_age="1s", extra=""))
    line = refused(runner.invoke(app, ["validate", str(file)]), file)
    assert "nests deeper" in line or "malformed YAML" in line


def test_alias_bomb_in_a_patch_file_is_refused(tmp_path):
    from hapticop.validation.patches import PatchError, load_patch

    text = f"[{{op: add, path: /doc, value: {bomb()}}}]"
    with pytest.raises(PatchError) as caught:
        load_patch(text, "bomb.yaml")
    assert "aliases expand" in caught.value.diagnostics[0].message


def test_fifo_is_refused_without_waiting_for_a_writer(tmp_path):
    fifo = tmp_path / "pipe.yaml"
    os.mkfifo(fifo)
    for command in ("validate", "compose"):
        done = subprocess.run([sys.executable, "-m", "hapticop.cli", command, str(fifo)], capture_output=True,
                              text=True, timeout=15, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
        output = done.stdout + done.stderr
        assert done.returncode in (1, 2) and "Traceback" not in output and "internal error" not in output, output
        assert f"{fifo}: error:" in output and "FIFO" in output


def test_character_device_is_refused():
    line = refused(runner.invoke(app, ["validate", "/dev/zero"]), "/dev/zero")
    assert "character device" in line


def test_symlink_loop_is_refused(tmp_path):
    loop = tmp_path / "loop.yaml"
    loop.symlink_to(tmp_path / "loop.yaml")
    refused(runner.invoke(app, ["validate", str(loop)]), loop)
    child = tmp_path / "child.yaml"
    child.write_text("extends: loop.yaml\n")
    line = refused(runner.invoke(app, ["validate", str(child)]), child)
    assert line.startswith(f"{child}:1:") and "loop.yaml" in line


def test_nul_byte_in_extends_is_located(tmp_path):
    child = tmp_path / "child.yaml"
    child.write_text('name: x\nextends: "base\\0.yaml"\n')
    line = refused(runner.invoke(app, ["validate", str(child)]), child)
    assert line.startswith(f"{child}:2:") and "'base\\0.yaml', which this file extends" in line


def test_an_integer_too_long_to_read_is_located(tmp_path):
    file = tmp_path / "huge.yaml"
    file.write_text(MINIMAL.format(period="1ms", dtype="int64", max_age="1s", extra="").replace(
        "block: counter", "block: counter\n    params: {step: " + "9" * 5000 + "}"))
    line = refused(runner.invoke(app, ["validate", str(file)]), file)
    assert line.startswith(f"{file}:16:20: error:") and "an integer of 5000 digits" in line, line
    assert "set_int_max_str_digits" not in line


def test_invalid_utf8_is_refused(tmp_path):
    file = tmp_path / "latin1.yaml"
    file.write_bytes(b"version: 1\nname: caf\xe9\n")
    line = refused(runner.invoke(app, ["validate", str(file)]), file)
    assert "not UTF-8" in line


@pytest.mark.parametrize("content", [b"- {op: remove, path: /name}\n# caf\xe9\n", None])
def test_patch_file_that_cannot_be_read_is_refused_before_asking_the_system(tmp_path, content):
    file = tmp_path / "patch.yaml"
    if content is None:
        os.mkfifo(file)
    else:
        file.write_bytes(content)
    result = runner.invoke(app, ["patch", "no-such-system", str(file)])
    assert result.exit_code == 2 and "Traceback" not in result.output, result.output
    assert f"{file}: error:" in result.output


def test_validate_finds_third_party_blocks_without_running_them(tmp_path, monkeypatch):
    package = tmp_path / "untrusted"
    (package / "sub").mkdir(parents=True)
    for init in (package / "__init__.py", package / "sub" / "__init__.py", package / "sub" / "blocks.py"):
        init.write_text(f"open({str(tmp_path / 'RAN')!r}, 'a').write({init.name!r})\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    file = tmp_path / "third-party.yaml"
    file.write_text("version: 1\nthreads:\n  main:\n    period: 1ms\n    deploy: main\n"
                    "    schedules:\n      0: [mediator, thing]\nactivities:\n  mediator: {block: mediator}\n"
                    "  thing: {block: 'untrusted.sub.blocks:Thing', params: {anything: 1}}\n")

    result = runner.invoke(app, ["validate", str(file)])
    assert result.exit_code == 0, result.output
    assert not (tmp_path / "RAN").exists()
    (line,) = [line for line in result.output.splitlines() if "warning:" in line]
    assert line.startswith(f"{file}:10:") and "not imported" in line

    missing = tmp_path / "missing.yaml"
    missing.write_text(file.read_text().replace("sub.blocks:", "sub.nothing:"))
    line = refused(runner.invoke(app, ["validate", str(missing)]), missing)
    assert "cannot find module 'untrusted.sub.nothing'" in line and not (tmp_path / "RAN").exists()

    result = runner.invoke(app, ["validate", "--import-blocks", str(file)])
    assert result.exit_code == 1 and "is not a hapticop Block class" in result.output, result.output
    assert (tmp_path / "RAN").read_text() == "__init__.py__init__.pyblocks.py"
