"""What happens to a run (modes, flags, life cycles) is recorded as `/events/KIND` channels."""

import json

from mcap.reader import make_reader

from hapticop.runtime.system import ExitStatus

from .runtime_helpers import compose
from .test_modes import MODES


def events(path, kind: str) -> list[dict]:
    with open(path, "rb") as stream:
        return [json.loads(m.data) for _, _, m in make_reader(stream).iter_messages(topics=[f"/events/{kind}"])]


def test_mode_switches_flags_and_life_cycles_are_channels(tmp_path):
    text = MODES + "streams:\n  count: {from: source.count, to: [probe.input]}\nrecord: {}\n"
    text = text.replace("[mediator, grip, gain]", "[mediator, grip, gain, source, probe]").replace(
        "activities:\n", "activities:\n  source: {block: counter}\n  probe: {block: echo}\n")
    result = compose(tmp_path, text, duration="300ms", name="m")
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    recording = tmp_path / "run-m" / "modes.mcap"

    modes = events(recording, "mode")
    assert [(m["entered"], m["left"], m["modes"]) for m in modes] == [(["held"], [], "held"), ([], ["held"], "none")]
    assert 0.09 <= modes[0]["time_s"] <= 0.11 and 0.19 <= modes[1]["time_s"] <= 0.21  # the grip's flag: 100 to 200 ms

    flags = events(recording, "flags")
    grip = [f["changed"]["grip.on"] for f in flags if "grip.on" in f["changed"]]
    assert grip == [False, True, False]  # as the run starts, then each change the recorder saw

    gain = [e for e in events(recording, "lifecycle") if e["owner"] == "gain"]
    assert gain[0]["from"] is None and gain[-1]["state"] == "done"
    assert "running" in {e["state"] for e in gain} | {s for e in gain for s in e["passed"]}
    passed = [e["from"] for e in gain[1:]]
    assert all(before is not None for before in passed)
