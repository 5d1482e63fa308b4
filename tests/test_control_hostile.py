"""A running system's control socket under hostile and careless clients: it answers every one,
goes on answering `status`, and its description does not change."""

from __future__ import annotations

import json
import threading
import time

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hapticop.runtime.control import request

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
]


def test_bad_requests_slow_clients_and_a_flood_leave_the_running_system_answering_and_unchanged(tmp_path):
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
    print("\ncontrol channel figures:", json.dumps(figures))


JSON = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=20),
    lambda children: st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=8), children, max_size=4),
    max_leaves=40,
)


def nested(depth: int, inner) -> object:
    for _ in range(depth):
        inner = [inner]
    return inner


def test_arbitrary_bytes_and_json_never_stop_the_running_system(tmp_path):
    def work(path, system):
        before = system.composition.model_dump()

        @settings(max_examples=50, deadline=None, suppress_health_check=list(HealthCheck))
        @given(st.binary(max_size=2000))
        def arbitrary_bytes(data):
            reply = send_raw(path, data)
            assert isinstance(reply.get("ok"), bool)
            timed_status(path)

        @settings(max_examples=50, deadline=None, suppress_health_check=list(HealthCheck))
        @given(JSON, st.integers(0, 200), st.sampled_from(["status", "patch", "other", None]))
        def arbitrary_json(value, depth, op):
            message = {"op": op, "text": value, "value": nested(depth, value)}
            reply = send_raw(path, json.dumps(message).encode() + b"\n")
            assert isinstance(reply.get("ok"), bool)
            if op != "status" or depth > 60:
                assert reply["ok"] is False
            timed_status(path)

        arbitrary_bytes()
        arbitrary_json()
        assert request(path, {"op": "status"}, timeout=PATIENCE_S)["ok"] is True
        assert system.composition.model_dump() == before

    while_running(tmp_path, work)
