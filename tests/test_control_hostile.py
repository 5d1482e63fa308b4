"""A running system's control socket under hostile and careless clients: it answers every one,
goes on answering `status`, and its description does not change."""

from __future__ import annotations

import json
import math
import socket
import struct
import threading
import time

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hapticop.composition.lcsm import State
from hapticop.control.client import request

from .control_helpers import (
    PATIENCE_S,
    SlowClients,
    answered_or_busy,
    flood,
    peak_rss_kib,
    send_raw,
    timed_status,
    while_running,
)

BAD_REQUESTS = [
    b"[" * 500_000 + b"\n",
    b'{"op": "patch", "text": ' + b"[" * 100 + b"]" * 100 + b"}\n",
    b"\n",
    b"[1]\n",
    b"\xff\xfe\x00\x01\n",
    b'{"op": "patch", "text": "x: " , "value": NaN}\n',
    b"{" + b" " * (2 << 20) + b"}\n",  # larger than any request may be
    b'{"op": "explode"}\n',
    b'{"op": "patch", "text": "' + b"a: &a [x]\\n" + b'"}\n',
    b'{"op": "patch", "text": 7}\n',
    # a few hundred bytes whose aliases would name 10**9 values in a `test` operation (the patch)
    json.dumps({"op": "patch", "text": "- op: test\n  path: /name\n  value:\n    l0: &l0 [x, x, x, x, x, x, x]\n"
                + "".join(f"    l{i}: &l{i} [" + ", ".join([f"*l{i - 1}"] * 10) + "]\n" for i in range(1, 10))}
               ).encode() + b"\n",
]


def test_bad_requests_slow_clients_and_a_flood_leave_the_running_system_answering_and_unchanged(tmp_path, figure):
    figures: dict[str, float] = {}

    def work(path, system):
        before = system.composition.model_dump()
        figures["peak_rss_before_kib"] = peak_rss_kib()
        for data in BAD_REQUESTS:
            reply = send_raw(path, data)
            assert reply["ok"] is False and reply["error"], (data[:40], reply)
            timed_status(path)
        assert send_raw(path, b'{"op": "status"', close=False)["ok"] is False  # no newline: its deadline
        figures["peak_rss_after_refused_kib"] = peak_rss_kib()

        with SlowClients(path, count=3, every_s=0.5):
            figures["slowest_status_with_3_slow_clients_s"] = max(timed_status(path) for _ in range(20))

        started = time.monotonic()
        flooded: list[dict] = []
        flooder = threading.Thread(target=lambda: flooded.extend(flood(path, clients=20, requests=50)))
        flooder.start()
        during = []
        while flooder.is_alive():
            during.append(timed_status(path))
        flooder.join()
        figures["flood_s"] = time.monotonic() - started
        figures["slowest_status_during_flood_s"] = max(during, default=0.0)
        figures["flood_busy"] = sum(1 for r in flooded if r.get("ok") is False)
        assert len(flooded) == 1000
        assert all(answered_or_busy(r) for r in flooded), [r for r in flooded if not answered_or_busy(r)][:3]

        timed_status(path)
        assert system.composition.model_dump() == before
        figures["peak_rss_end_kib"] = peak_rss_kib()

    while_running(tmp_path, work)
    figure("control channel: " + json.dumps(figures))


VALID = "activities: {noise: {params: {sigma: 2.0}}}"


def test_known_fields_of_the_wrong_type_are_refused_not_guessed(tmp_path):
    """A `dry_run` of "no" or 0 must not decide whether a running system changes: a patch request
    whose fields have the wrong type is refused, naming the field, and changes nothing."""

    def work(path, system):
        noise = system.runners["noise"].block
        before, params = system.composition.model_dump(), noise.params
        for fields, error in [
            ({"dry_run": "no"}, "'dry_run' must be true or false, not a string"),
            ({"dry_run": 0}, "'dry_run' must be true or false, not a number"),
            ({"dry_run": None}, "'dry_run' must be true or false, not null"),
            ({"file": ["a.yaml"]}, "'file' must be a file name, not an array"),
            ({"text": {"activities": {"noise": {"params": {"sigma": 2.0}}}}}, "'text' must be the patch's text"),
            ({"text": None}, "'text' must be the patch's text, not null"),
        ]:
            reply = request(path, {"op": "patch", "text": VALID, **fields}, timeout=PATIENCE_S)
            assert reply["ok"] is False and reply["error"].startswith(f"malformed request: {error}"), (fields, reply)
            assert system.composition.model_dump() == before and noise.params is params
        missing = request(path, {"op": "patch"}, timeout=PATIENCE_S)
        assert missing["ok"] is False and "needs 'text'" in missing["error"]
        dry = request(path, {"op": "patch", "text": VALID, "dry_run": True, "file": "sigma.yaml"}, timeout=PATIENCE_S)
        assert dry["ok"] is True and dry["applied"] is False and system.composition.model_dump() == before
        applied = request(path, {"op": "patch", "text": VALID, "dry_run": False}, timeout=PATIENCE_S)
        assert applied["ok"] is True and applied["applied"] is True
        # the block takes its new parameters before its next step, which may come after the reply
        deadline = time.monotonic() + PATIENCE_S
        while noise.params.sigma != 2.0:
            assert time.monotonic() < deadline, "the applied patch never reached the block"
            time.sleep(0.01)

    while_running(tmp_path, work)


# -- property tests: whatever arrives on the socket, the running system answers and stays as it was ----------

EXAMPLES = 300  # per property; the file takes about 25 s on two busy cores


class Raw:
    """A token written into the JSON text as it is: what json.dumps cannot or will not write."""

    def __init__(self, text: str):
        self.text = text

    def __repr__(self) -> str:
        return f"Raw({self.text[:20]!r})"


NOT_FINITE = ("NaN", "Infinity", "-Infinity")  # tokens Python's parser accepts and the server refuses
ODD_NUMBERS = [Raw(t) for t in (*NOT_FINITE, "1e999", "-1e400", "9" * 5000, "1" + "0" * 400, "-0", "4.9e-324",
                                "1.7976931348623157e308", "0.1e-99999")]
ODD_TEXT = ["", " ", "\n", "\x00", "\ud800", "\U0001f4a5", "&a [*a, *a]", "*a", "!!python/object:os.system",
            "1ms", "-1ms", "0s", ".nan", ".inf", "1e999ms", "tests.blocks:Noise", "os:system", "mediator", "echo"]
SCALARS = (st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False, allow_infinity=False)
           | st.text(max_size=20) | st.sampled_from(ODD_TEXT) | st.sampled_from(ODD_NUMBERS))
JSON = st.recursive(
    SCALARS,
    lambda children: st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=8), children, max_size=4),
    max_leaves=30,
)


def encode(value: object) -> str:
    """JSON text of `value`, with Raw tokens written as they are."""
    if isinstance(value, Raw):
        return value.text
    if isinstance(value, list):
        return "[" + ", ".join(encode(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{json.dumps(k)}: {encode(v)}" for k, v in value.items()) + "}"
    return json.dumps(value)


def nested(depth: int, inner: object) -> object:
    for _ in range(depth):
        inner = [inner]
    return inner


def carries(value: object, tokens) -> bool:
    """Whether one of the Raw `tokens` is somewhere in `value`."""
    if isinstance(value, Raw):
        return value.text in tokens
    if isinstance(value, list | dict):
        return any(carries(v, tokens) for v in (value.values() if isinstance(value, dict) else value))
    return False


TOO_LONG = ("9" * 5000,)  # an integer longer than a request may carry (and than Python reads: 4300 digits)


def depth_of(value: object) -> int:
    if isinstance(value, list | dict):
        return 1 + max((depth_of(v) for v in (value.values() if isinstance(value, dict) else value)), default=0)
    return 0


def a_status_request(line: bytes) -> bool:
    """Whether the server should take `line` (what precedes the first newline) as a good `status` request."""
    def refuse(name: str) -> float:
        raise ValueError(name)

    try:
        message = json.loads(line, parse_constant=refuse)
    except (ValueError, RecursionError):
        return False
    return isinstance(message, dict) and message.get("op") == "status" and depth_of(message) <= 64


class Watch:
    """What must hold after every request: `status` answers (within PATIENCE_S, else the test fails),
    every activity still runs, and the description and the noise block's parameters are as they were."""

    def __init__(self, path, system):
        self.path, self.system = path, system
        self.noise = system.runners["noise"].block
        self.before = system.composition.model_dump()
        self.params = self.noise.params
        self.slowest_status_s = 0.0
        self.applied = 0

    def check(self, reply: dict | None = None) -> None:
        self.slowest_status_s = max(self.slowest_status_s, timed_status(self.path))
        if reply is not None and reply.get("ok") is True and reply.get("applied") is True:
            # a valid patch: it may change the system, and the new state is the one to keep
            self.applied += self.system.composition.model_dump() != self.before
            self.before = self.system.composition.model_dump()
            self.noise = self.system.runners["noise"].block
            # A retune is taken by the block at its next step, on its own thread: the parameters to keep are
            # the ones it holds once settled. A reconfiguration is asked by a request flag its activity takes
            # at its next step: until then it still says running. Settled is no retune or request left and
            # every activity running, seen twice apart (the flag is taken and the state left in one step,
            # which a poll may fall between).
            deadline = time.monotonic() + PATIENCE_S
            while not (self.settled() and time.sleep(0.05) is None and self.settled()):
                assert time.monotonic() < deadline, "an activity did not come back to running after a patch"
                time.sleep(0.005)
            self.params = self.noise.params
        assert self.system.composition.model_dump() == self.before
        assert self.noise.params is self.params
        assert self.running()

    def running(self) -> bool:
        return all(self.system.state(name) is State.RUNNING for name in ACTIVITIES)

    def settled(self) -> bool:
        """No re-configuration asked and not yet taken, and every activity running."""
        asked = any(self.system.flag(f"{name}.lcsm.{request}") for name in ACTIVITIES
                    for request in ("request_resource_configuration", "request_capability_configuration"))
        retuning = any(runner.retuned is not None for runner in self.system.runners.values())
        return not asked and not retuning and self.running()


ACTIVITIES = ("mediator", "noise", "recorder")


FRAGMENTS = st.sampled_from([
    b"\n", b"\r\n", b"\x00", b"\xff", b"\xfe\xff", b"\xc3\x28", b"\xed\xa0\x80", b"\xf4\x90\x80\x80", b"\x80",
    b"{", b"}", b"[", b"]", b'"', b"\\", b":", b",", b" ", b"NaN", b"-Infinity", b"1e999", b"9" * 400,
    b'"op"', b'"status"', b'"patch"', b'"text"', b'"dry_run"', b"true", b"null",
    b'{"op": "status"', b'{"op": "status"}', b'{"op": "patch", "text": "', b"[" * 70, b"]" * 70,
])
BYTES = st.binary(max_size=4096) | st.lists(FRAGMENTS | st.binary(max_size=16), max_size=60).map(b"".join)


def test_arbitrary_bytes_never_harm_the_running_system(tmp_path, figure):
    """Random bytes, embedded newlines and NULs, invalid UTF-8, partial lines: each gets one line
    back (an error unless its first line is a good status request), or the client hangs up first."""

    def work(path, system):
        watch = Watch(path, system)

        @settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck))
        @given(BYTES, st.sampled_from(["reads its reply", "hangs up", "resets"]))
        def arbitrary_bytes(data, client):
            if client == "reads its reply":
                reply = send_raw(path, data)
                line = data.split(b"\n", 1)[0]
                assert reply["ok"] is a_status_request(line), (data[:80], reply)
                assert reply["ok"] or isinstance(reply["error"], str) and reply["error"], reply
            else:
                with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as rude:
                    rude.settimeout(PATIENCE_S)
                    rude.connect(str(path))
                    if client == "resets":  # close with an RST, whatever the server still has to say
                        rude.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
                    try:
                        rude.sendall(data)
                    except OSError:
                        pass  # the server answered and closed before we finished: fine
            watch.check()

        arbitrary_bytes()
        figure(f"slowest status between random byte requests: {watch.slowest_status_s:.3f} s")

    while_running(tmp_path, work)


FIELD_VALUES = JSON | st.tuples(st.integers(0, 150), JSON).map(lambda d: nested(*d))
OPS = st.sampled_from(["status", "patch", "Status", "", "patch ", "explode", "status\x00"]) | JSON
REQUESTS = st.fixed_dictionaries({}, optional={"op": OPS, "text": FIELD_VALUES, "file": FIELD_VALUES,
                                               "dry_run": FIELD_VALUES, "extra": FIELD_VALUES})


def test_arbitrary_json_requests_never_harm_the_running_system(tmp_path, figure):
    """Random objects of random depth, huge numbers, NaN and Infinity, known fields of the wrong type:
    a status request is answered, everything else refused, and nothing changes."""

    def work(path, system):
        watch = Watch(path, system)

        @settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck))
        @given(REQUESTS | JSON)
        def arbitrary_json(message):
            text = encode(message).encode("utf-8", "surrogatepass")
            reply = send_raw(path, text + b"\n")
            assert isinstance(reply.get("ok"), bool), reply
            malformed = (not isinstance(message, dict) or depth_of(message) > 64 or carries(message, NOT_FINITE)
                         or carries(message, TOO_LONG))
            if not malformed and message.get("op") == "status":
                assert reply["ok"] is True and reply["status"]["name"] == "pipeline", reply
            else:
                assert reply["ok"] is False and reply["error"], (message, reply)
            if depth_of(message) <= 64 and (carries(message, NOT_FINITE) or carries(message, TOO_LONG)):
                assert "a request may carry" in reply["error"], reply  # said as such, not as Python's limit
            watch.check()

        arbitrary_json()
        figure(f"slowest status between random JSON requests: {watch.slowest_status_s:.3f} s")

    while_running(tmp_path, work)


SEGMENTS = st.sampled_from([
    "activities", "threads", "streams", "coordination", "patches", "name", "version", "doc", "noise", "recorder",
    "mediator", "main", "slow", "params", "sigma", "capacity", "block", "period", "priority", "cpus", "deploy",
    "schedules", "0", "1", "-", "samples", "from", "to", "~0", "~1", "", "ghost", "\U0001f4a5",
]) | st.text(max_size=6)
POINTERS = st.lists(SEGMENTS, max_size=5).map(lambda parts: "".join(f"/{p}" for p in parts)) | st.text(max_size=10)
OPERATION = st.fixed_dictionaries(
    {"op": st.sampled_from(["add", "remove", "replace", "move", "copy", "test", "explode"]) | JSON, "path": POINTERS},
    optional={"value": JSON, "from": POINTERS},
)


def not_finite(document: object, where: str = ""):
    """Where a number in `document` is NaN or infinite."""
    if isinstance(document, float) and not math.isfinite(document):
        yield where
    elif isinstance(document, dict):
        for key, value in document.items():
            yield from not_finite(value, f"{where}/{key}")
    elif isinstance(document, list | tuple):
        for index, value in enumerate(document):
            yield from not_finite(value, f"{where}/{index}")


def merge_patch(parts: list[str], value: object) -> object:
    for part in reversed(parts):
        value = {part: value}
    return value


# Real places in the running pipeline, and values a YAML reader turns into numbers Python's JSON would not.
REAL_POINTERS = st.sampled_from([
    "/activities/noise/params/sigma", "/activities/noise/params", "/activities/recorder/params/capacity",
    "/threads/slow/period", "/threads/main/period", "/threads/main/schedules/0", "/threads/slow/schedules/0/-",
    "/streams/samples/to", "/streams/samples/max_age", "/activities/noise/block", "/activities/ghost", "/name",
])
YAML_NUMBERS = st.sampled_from([Raw(t) for t in (".nan", ".NaN", ".inf", "-.inf", "+.inf", "1e999", "-1e999")])
PLAUSIBLE = (st.floats(-10, 1e6) | st.integers(-5, 200_000) | YAML_NUMBERS
             | st.sampled_from(["1ms", "10ms", "20ms", "0s", "-1ms", "1e999ms", "mediator", "noise", "recorder"])
             | st.lists(st.sampled_from(["mediator", "noise", "recorder", "ghost"]), max_size=4))
NEAR_VALID_VALUES = (PLAUSIBLE | st.dictionaries(st.sampled_from(["sigma", "capacity"]), PLAUSIBLE, min_size=1)
                     | JSON)
NEAR_VALID = (
    st.lists(st.fixed_dictionaries({"op": st.sampled_from(["add", "replace", "test"]), "path": REAL_POINTERS,
                                    "value": NEAR_VALID_VALUES}), min_size=1, max_size=3)
    | st.builds(lambda pointer, value: merge_patch(pointer.split("/")[1:], value), REAL_POINTERS, NEAR_VALID_VALUES)
)
PATCHES = (st.lists(OPERATION, min_size=1, max_size=4)
           | st.builds(merge_patch, st.lists(SEGMENTS, min_size=1, max_size=5), JSON)
           | NEAR_VALID)


def test_random_patches_change_nothing_unless_valid(tmp_path, figure):
    """JSON Patches and merge patches of random paths and values, sent for real: a refused one
    changes neither the description nor the running block; NaN and Infinity are never applied."""

    def work(path, system):
        watch = Watch(path, system)

        @settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck))
        @given(PATCHES, st.sampled_from([None, False, 0, "", [], {}, True]))
        def random_patch(patch, dry_run):
            message = {"op": "patch", "text": encode(patch)}
            if dry_run is not None:
                message["dry_run"] = dry_run
            reply = send_raw(path, json.dumps(message).encode() + b"\n")
            assert isinstance(reply.get("ok"), bool), reply
            assert reply["ok"] or reply["error"], reply
            watch.check(reply)
            assert math.isfinite(watch.noise.params.sigma)
            assert not list(not_finite(system.composition.model_dump())), (patch, reply)

        random_patch()
        figure(f"slowest status between random patches: {watch.slowest_status_s:.3f} s; "
               f"{watch.applied} of them valid and applied")

    while_running(tmp_path, work)
