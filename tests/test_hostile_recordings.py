"""Hostile recordings given to `info`, `plot`, `replay`, `report` and `recover`: a recording is data.

Recordings are files people mail each other. Every file here is made by the test from a real
recording (or from nothing): a chunk of a few kB that inflates to 1 GiB (declaring it, or
declaring a small size), records and fields that declare 3 GiB or 1 TiB, a file that is only
the magic, a 100,000-deep parameters.json and composition, a FIFO, a directory, a device; and
`plot --csv` into /dev/full, a FIFO nobody reads and a directory. Each file goes to every
command in a child process limited in address space (RLIMIT_AS) and time: each must end with
exit 1 or 2 and a line `error: ...` naming the file, never a traceback, a hang or an
out-of-memory. A hypothesis test flips bits, cuts and rewrites length fields of the real
recording and holds every command to the same rule (exit 0 allowed: a flip in a sample's
value leaves a valid file).

A recording's composition names its blocks: `replay` and `report` import no module for them
unless `--trust-blocks` is given, and never one beside the recording or in the current
directory, even when run as `python -m hapticop.cli` from the recording's folder.
"""

from __future__ import annotations

import json
import os
import resource
import struct
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, DataEnd, Footer, Header, Schema, Statistics

from .conftest import ROOT
from .recordings import rewrite_recording
from .runtime_helpers import compose
from .test_recording import counters

pytestmark = pytest.mark.timeout(600)

MAGIC = b"\x89MCAP0\r\n"
GIB = 1 << 30
ADDRESS_SPACE = 1536 << 20  # the child's whole address space: Python, numpy, mcap and the CLI fit in a third
PATIENCE_S = 120  # a bound on a hang, never a speed requirement
COMMANDS = ("info", "plot", "replay", "report", "recover")

# Runs each command line of its standard input (JSON) through the CLI in this one process and prints, per
# line, its exit code, its output and the type of any exception it ended in.
DRIVER = textwrap.dedent("""
    import json, sys
    from typer.testing import CliRunner
    from hapticop.cli.main import app
    runner = CliRunner()
    for argv in json.loads(sys.stdin.read()):
        result = runner.invoke(app, argv)
        crash = None if result.exception is None or isinstance(result.exception, SystemExit) else \\
            type(result.exception).__name__
        print(json.dumps({"argv": argv, "code": result.exit_code, "output": result.output, "crash": crash}),
              flush=True)
""")


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("real")
    compose(tmp, counters(), duration="0.3s", name="c")
    return tmp / "run-c" / "c.mcap"


def _limits() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))


def run_cli(lines: list[list[str]], cwd: Path = ROOT, env: dict | None = None) -> list[dict]:
    """Each command line's outcome, run in a child process bounded in memory and time."""
    environment = {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1",
                   "MPLBACKEND": "Agg", **(env or {})}
    environment.pop("DISPLAY", None)
    done = subprocess.run([sys.executable, "-c", DRIVER], input=json.dumps(lines), capture_output=True, text=True,
                          timeout=PATIENCE_S, cwd=cwd, env=environment, preexec_fn=_limits)
    assert done.returncode == 0, done.stderr[-3000:]
    return [json.loads(line) for line in done.stdout.splitlines()]


def every_command(file: Path, scratch: Path) -> list[list[str]]:
    return [["info", str(file)], ["plot", str(file), "count", "--csv", str(scratch / "out.csv")],
            ["replay", str(file), "-a", "counter"], ["report", str(file), "-o", str(scratch / "report")],
            ["recover", str(file), "-o", str(scratch / f"{file.name}.recovered.mcap")]]


def refused(outcome: dict, file: Path) -> str:
    """The one error line of a command that refused `file`."""
    text = f"{outcome['argv']}: {outcome['output']}"
    assert outcome["crash"] is None, text
    assert "Traceback" not in outcome["output"] and "internal error" not in outcome["output"], text
    if outcome["argv"][0] == "recover":  # it says what it could keep, and exits 1 when that is nothing
        assert outcome["code"] in (1, 2), text
        return outcome["output"]
    assert outcome["code"] in (1, 2), text
    errors = [line for line in outcome["output"].splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and str(file) in errors[0], text
    return errors[0]


# -- files made here ----------------------------------------------------------------------

def _summary(path: Path):
    with open(path, "rb") as stream:
        return make_reader(stream).get_summary()


def crafted(real: Path, chunk: bytes, uncompressed_size: int) -> bytes:
    """A file with the real recording's schemas and channels, one zstd chunk of these bytes and a
    summary saying so."""
    summary = _summary(real)
    out = RecordBuilder()
    out.write(MAGIC)
    Header(profile="", library="hostile").write(out)
    for schema in summary.schemas.values():
        Schema(id=schema.id, name=schema.name, encoding=schema.encoding, data=schema.data).write(out)
    for channel in summary.channels.values():
        Channel(id=channel.id, schema_id=channel.schema_id, topic=channel.topic,
                message_encoding=channel.message_encoding, metadata=dict(channel.metadata)).write(out)
    Chunk(message_start_time=0, message_end_time=1, uncompressed_size=uncompressed_size, uncompressed_crc=0,
          compression="zstd", data=chunk).write(out)
    DataEnd(data_section_crc=0).write(out)
    summary_start = out.count
    for schema in summary.schemas.values():
        Schema(id=schema.id, name=schema.name, encoding=schema.encoding, data=schema.data).write(out)
    for channel in summary.channels.values():
        Channel(id=channel.id, schema_id=channel.schema_id, topic=channel.topic,
                message_encoding=channel.message_encoding, metadata=dict(channel.metadata)).write(out)
    Statistics(message_count=1, schema_count=len(summary.schemas), channel_count=len(summary.channels),
               attachment_count=0, metadata_count=0, chunk_count=1, message_start_time=0, message_end_time=1,
               channel_message_counts={cid: 1 for cid in summary.channels}).write(out)
    Footer(summary_start=summary_start, summary_offset_start=0, summary_crc=0).write(out)
    out.write(MAGIC)
    return out.end()


def inflating_to_a_gib(real: Path) -> bytes:
    """zstd of one 1 GiB message on the `count` channel: about 30 kB."""
    import zstandard

    channel = next(cid for cid, c in _summary(real).channels.items() if c.topic.endswith("count"))
    payload = GIB - 64
    head = struct.pack("<BQHIQQ", Opcode.MESSAGE, 2 + 4 + 8 + 8 + payload, channel, 0, 0, 0)
    compressor = zstandard.ZstdCompressor(level=1).compressobj()
    parts, zeros = [compressor.compress(head)], bytes(1 << 20)
    left = payload
    while left:
        piece = zeros[: min(left, len(zeros))]
        parts.append(compressor.compress(piece))
        left -= len(piece)
    parts.append(compressor.flush())
    return b"".join(parts)


def _u64(data: bytearray, offset: int, value: int) -> bytes:
    data[offset:offset + 8] = struct.pack("<Q", value)
    return bytes(data)


def length_fields(real: Path) -> dict[str, int]:
    """Where the real recording's first chunk and its composition attachment declare lengths."""
    summary = _summary(real)
    chunk = summary.chunk_indexes[0].chunk_start_offset
    data = real.read_bytes()
    (compression,) = struct.unpack_from("<I", data, chunk + 1 + 8 + 8 + 8 + 8 + 4)
    attachment = next(a for a in summary.attachment_indexes if a.name == "composition.yaml").offset
    at = attachment + 1 + 8 + 8 + 8
    for _ in range(2):  # name, media type
        (n,) = struct.unpack_from("<I", data, at)
        at += 4 + n
    return {"chunk record": chunk + 1, "chunk inflated size": chunk + 1 + 8 + 8 + 8,
            "chunk data": chunk + 1 + 8 + 8 + 8 + 8 + 4 + 4 + compression,
            "attachment record": attachment + 1, "attachment data": at}



def hostile(real: Path, folder: Path) -> dict[str, Path]:
    """Every hostile file, by what it is."""
    files: dict[str, Path] = {}

    def put(name: str, data: bytes) -> None:
        files[name] = folder / f"{name.replace(' ', '-')}.mcap"
        files[name].write_bytes(data)

    bomb = inflating_to_a_gib(real)
    assert len(bomb) < 200_000
    put("chunk inflating to 1 GiB", crafted(real, bomb, GIB))
    put("chunk inflating to 1 GiB, declaring 1 kB", crafted(real, bomb, 1000))
    put("magic only", MAGIC)
    fields = length_fields(real)
    for name, offset in fields.items():
        for size, said in ((3 * GIB, "3 GiB"), (1 << 40, "1 TiB")):
            put(f"{name} declaring {said}", _u64(bytearray(real.read_bytes()), offset, size))
    deep = 100_000
    files["deep parameters.json"] = rewrite_recording(
        real, folder / "deep-parameters.mcap", replaced={"parameters.json": b"[" * deep + b"]" * deep})
    files["deep composition.yaml"] = rewrite_recording(
        real, folder / "deep-composition.mcap", replaced={"composition.yaml": b"version: " + b"[" * deep + b"]" * deep})
    os.mkfifo(folder / "fifo.mcap")
    files["FIFO"] = folder / "fifo.mcap"
    (folder / "directory.mcap").mkdir()
    files["directory"] = folder / "directory.mcap"
    files["character device"] = Path("/dev/zero")
    return files


# What a command may answer, in the same bounds, because it never reads the damaged part: info reads
# the summary, never an unindexed chunk; only replay and report read the attached parameters and composition.
ANSWERING = {"chunk inflating to 1 GiB": ("info",), "chunk inflating to 1 GiB, declaring 1 kB": ("info",),
             "deep parameters.json": ("info", "plot", "recover"), "deep composition.yaml": ("info", "plot", "recover")}


def test_every_hostile_file_is_refused_in_one_line_in_bounded_time_and_memory(recording, tmp_path):
    files = hostile(recording, tmp_path)
    lines = [line for file in files.values() for line in every_command(file, tmp_path)]
    outcomes = run_cli(lines)
    assert len(outcomes) == len(lines)
    by_file = {str(file): name for name, file in files.items()}
    said = {}
    for outcome in outcomes:
        file = Path(outcome["argv"][1])
        name = by_file[str(file)]
        if outcome["argv"][0] in ANSWERING.get(name, ()):
            assert outcome["code"] == 0 and outcome["crash"] is None, outcome
            continue
        said[(name, outcome["argv"][0])] = refused(outcome, file)
    assert "more than hapticop inflates" in said[("chunk inflating to 1 GiB", "plot")]
    assert "more than hapticop inflates" in said[("chunk inflating to 1 GiB, declaring 1 kB", "plot")]
    assert "inflates to more than" in said[("chunk inflating to 1 GiB, declaring 1 kB", "recover")]
    assert "nests deeper than 64" in said[("deep parameters.json", "replay")]
    assert "nests deeper than 64" in said[("deep composition.yaml", "report")]
    for command in ("info", "plot", "replay", "report", "recover"):
        assert "it is a FIFO" in said[("FIFO", command)]
        assert "it is a directory" in said[("directory", command)]
        assert "it is a character device" in said[("character device", command)]


def test_the_real_recording_passes_the_same_child(recording, tmp_path):
    """The bounds leave a real recording alone: the same limits, every command answers."""
    outcomes = run_cli(every_command(recording, tmp_path))
    codes = {o["argv"][0]: (o["code"], o["crash"]) for o in outcomes}
    assert codes["info"] == (0, None) and codes["plot"] == (0, None) and codes["replay"] == (0, None), outcomes
    assert codes["recover"] == (0, None), outcomes
    assert "count" in (tmp_path / "out.csv").read_text()


@pytest.mark.parametrize("target", ["/dev/full", "fifo", "directory"])
def test_plot_csv_into_what_cannot_take_it_is_one_line(recording, tmp_path, target):
    if target == "fifo":
        os.mkfifo(tmp_path / "fifo")
    if target == "directory":
        (tmp_path / "directory").mkdir()
    where = target if target.startswith("/") else str(tmp_path / target)
    (outcome,) = run_cli([["plot", str(recording), "count", "--csv", where]])
    text = outcome["output"]
    assert outcome["code"] == 1 and outcome["crash"] is None and "Traceback" not in text, outcome
    (line,) = [line for line in text.splitlines() if line.startswith("error:")]
    assert line.startswith(f"error: {where}: cannot write the CSV: "), line


# -- mutations of the real recording ------------------------------------------------------

MUTATE = settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)


@st.composite
def mutations(draw, size: int, fields: dict[str, int]):
    kind = draw(st.sampled_from(["flip", "truncate", "length"]))
    if kind == "flip":
        return ("flip", [draw(st.integers(0, size * 8 - 1)) for _ in range(draw(st.integers(1, 24)))])
    if kind == "truncate":
        return ("truncate", draw(st.integers(0, size - 1)))
    return ("length", draw(st.sampled_from(sorted(fields))),
            draw(st.sampled_from([0, 1, 7, size, size + 1, 3 * GIB, 1 << 40, (1 << 64) - 1])))


def mutated(data: bytes, fields: dict[str, int], mutation) -> bytes:
    out = bytearray(data)
    if mutation[0] == "flip":
        for bit in mutation[1]:
            out[bit // 8] ^= 1 << (bit % 8)
        return bytes(out)
    if mutation[0] == "truncate":
        return bytes(out[: mutation[1]])
    return _u64(out, fields[mutation[1]], mutation[2])


def test_mutated_recordings_end_in_a_line_or_an_answer_never_a_crash(recording, tmp_path):
    """Bit flips, cuts and rewritten length fields of the real recording: each file goes to every
    command in the bounded child, which must answer (exit 0, or 3 for a recovery that lost some)
    or refuse in one line; never a traceback, a hang or an exhausted memory."""
    data = recording.read_bytes()
    fields = length_fields(recording)
    drawn = []

    @MUTATE
    @given(mutations(len(data), fields))
    def collect(mutation) -> None:
        drawn.append(mutation)

    collect()
    lines = []
    for k, mutation in enumerate(drawn):
        file = tmp_path / f"m{k}.mcap"
        file.write_bytes(mutated(data, fields, mutation))
        lines += [line for line in every_command(file, tmp_path) if line[0] != "recover"]
        lines.append(["recover", str(file), "-o", str(tmp_path / f"m{k}.recovered.mcap")])
    outcomes = run_cli(lines)
    assert len(outcomes) == len(lines)
    for outcome in outcomes:
        text = f"{outcome['argv']}: {outcome['output']}"
        assert outcome["crash"] is None and "Traceback" not in outcome["output"], text
        allowed = (0, 1, 2, 3) if outcome["argv"][0] == "recover" else (0, 1, 2)
        assert outcome["code"] in allowed, text
        if outcome["code"] == 2 or (outcome["code"] == 1 and outcome["argv"][0] in ("info", "plot")):
            errors = [line for line in outcome["output"].splitlines() if line.startswith("error:")]
            assert len(errors) == 1 and outcome["argv"][1] in errors[0], text


# -- a recording's blocks are not code ----------------------------------------------------

MARK = "imported {name}"


def _module(folder: Path, name: str, marker: Path) -> None:
    """A module that leaves a mark when imported, with an echo block in it."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{name}.py").write_text(
        f"open({str(marker)!r}, 'a').write({MARK.format(name=name)!r} + '\\n')\n"
        "from hapticop.blocks.basic import Echo\n")


def naming(real: Path, target: Path, block: str) -> Path:
    """The real recording with its `echo` activity's block named `block`."""
    with open(real, "rb") as stream:
        text = next(a for a in make_reader(stream).iter_attachments() if a.name == "composition.yaml").data.decode()
    assert "echo: {block: echo}" in text or "block: echo" in text, text
    changed = text.replace("block: echo", f"block: '{block}'", 1)
    return rewrite_recording(real, target, replaced={"composition.yaml": changed.encode()})


def test_replay_and_report_import_nothing_a_recording_names_unless_trusted(recording, tmp_path):
    marker = tmp_path / "marks"
    mailed = tmp_path / "mailed"
    _module(mailed, "beside", marker)  # a module mailed along with the recording
    installed = tmp_path / "site"
    _module(installed, "installed", marker)  # one on PYTHONPATH, as an installed package is
    env = {"PYTHONPATH": f"{ROOT}{os.pathsep}{installed}"}
    near = naming(recording, mailed / "near.mcap", "beside:Echo")
    far = naming(recording, mailed / "far.mcap", "installed:Echo")

    untrusted = [[command, str(file), *(["-a", "counter"] if command == "replay" else [])]
                 for file in (near, far) for command in ("replay", "report")]
    for outcome in run_cli(untrusted, cwd=mailed, env=env):  # run from the recording's folder
        line = refused(outcome, Path(outcome["argv"][1]))
        assert "is not built in" in line and "--trust-blocks" in line, line
    assert not marker.exists(), marker.read_text()

    # `python -m` puts the current directory first on sys.path: trusted or not, never from there.
    done = subprocess.run([sys.executable, "-m", "hapticop.cli", "replay", "--trust-blocks", str(near)],
                          capture_output=True, text=True, timeout=PATIENCE_S, cwd=mailed,
                          env={**os.environ, **env})
    assert done.returncode == 2 and "cannot import module 'beside'" in done.stderr, done.stderr
    assert not marker.exists(), marker.read_text()

    (outcome,) = run_cli([["replay", "--trust-blocks", str(far), "-a", "counter"]], cwd=mailed, env=env)
    assert outcome["code"] == 0, outcome
    assert marker.read_text() == MARK.format(name="installed") + "\n"
