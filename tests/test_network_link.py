"""The emulated link: delays within delay ± jitter, seeded chances, identical reruns, order kept unless asked."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from hapticop.network.link import EmulatedLink, LinkParams, MessageLink

Delivery = tuple[int, float, float, tuple]


def run(params: LinkParams, sends: int, period_s: float = 0.001, width: int = 2) -> list[Delivery]:
    """Send a packet every period (its payload its index) and take everything as it falls due:
    (sequence, sent, received, payload) per delivery."""
    link = EmulatedLink(params, width)
    out = []
    horizon = sends + int((params.delay_s + params.jitter_s) / period_s) + 2
    for tick in range(horizon):
        now = tick * period_s
        if tick < sends:
            link.send(now, np.full(width, float(tick)))
        while (slot := link.receive(now)) >= 0:
            out.append((link.sequence(slot), link.sent_s(slot), now, tuple(link.payload(slot))))
    return out


delays = st.floats(0.0, 0.5)
fractions = st.floats(0.0, 1.0)


@settings(max_examples=40, deadline=None)
@given(delay=delays, jitter_fraction=fractions, reorder=st.booleans(), seed=st.integers(0, 2**32))
def test_each_delivery_falls_within_delay_plus_or_minus_jitter(delay, jitter_fraction, reorder, seed):
    period = 0.001
    params = LinkParams(delay_s=delay, jitter_s=delay * jitter_fraction, reorder=reorder, seed=seed)
    deliveries = run(params, 300, period)
    assert len(deliveries) == 300
    for sequence, sent, received, payload in deliveries:
        assert payload == (float(sequence),) * 2
        latency = received - sent
        # received on the first tick at or after the due time
        assert latency >= params.delay_s - params.jitter_s - 1e-9
        assert latency < params.delay_s + params.jitter_s + period + 1e-9


@settings(max_examples=30, deadline=None)
@given(delay=delays, jitter_fraction=fractions, seed=st.integers(0, 2**32))
def test_without_reorder_packets_arrive_in_the_order_sent(delay, jitter_fraction, seed):
    params = LinkParams(delay_s=delay, jitter_s=delay * jitter_fraction, duplicate=0.2, loss=0.1, seed=seed)
    sequences = [d[0] for d in run(params, 300)]
    assert sequences == sorted(sequences)


def test_with_reorder_large_jitter_lets_packets_overtake():
    params = LinkParams(delay_s=0.05, jitter_s=0.02, reorder=True, seed=3)
    sequences = [d[0] for d in run(params, 500)]
    assert sorted(sequences) == list(range(500))
    assert sequences != sorted(sequences)
    overtaken = sum(1 for a, b in zip(sequences, sequences[1:]) if b < a)
    assert overtaken > 50


def test_with_reorder_but_jitter_below_the_sending_interval_order_is_kept():
    params = LinkParams(delay_s=0.05, jitter_s=0.0004, reorder=True, seed=3)
    sequences = [d[0] for d in run(params, 500)]
    assert sequences == list(range(500))


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**32), loss=st.sampled_from([0.01, 0.05, 0.2, 0.5]))
def test_loss_rate_matches_its_probability(seed, loss):
    n = 20000
    link = EmulatedLink(LinkParams(loss=loss, seed=seed), 1)
    for i in range(n):
        link.send(i * 1e-3, 0.0)
        while link.receive(i * 1e-3) >= 0:
            pass
    sigma = math.sqrt(n * loss * (1 - loss))
    assert abs(link.lost - n * loss) < 5 * sigma
    assert link.delivered == n - link.lost
    assert link.in_flight == 0


def test_duplicates_arrive_twice_with_one_sequence_number():
    params = LinkParams(delay_s=0.01, jitter_s=0.002, duplicate=0.3, seed=11)
    deliveries = run(params, 2000)
    link_copies = len(deliveries) - 2000
    assert abs(link_copies - 600) < 5 * math.sqrt(2000 * 0.3 * 0.7)
    counts = np.bincount([d[0] for d in deliveries])
    assert set(counts.tolist()) == {1, 2}


def test_reruns_are_bit_identical_and_seeds_differ():
    params = LinkParams(delay_s=0.1, jitter_s=0.01, loss=0.05, duplicate=0.02, reorder=True, seed=42)
    first, second = run(params, 3000), run(params, 3000)
    assert first == second
    other = run(LinkParams(delay_s=0.1, jitter_s=0.01, loss=0.05, duplicate=0.02, reorder=True, seed=43), 3000)
    assert other != first


def test_the_same_seed_gives_the_same_chances_whatever_the_settings():
    """Common random numbers: the packets lost at 5 % are among those lost at 20 %."""

    def lost(loss: float) -> set[int]:
        delivered = {d[0] for d in run(LinkParams(delay_s=0.02, jitter_s=0.002, loss=loss, seed=5), 2000)}
        return set(range(2000)) - delivered

    assert lost(0.05) <= lost(0.2)
    assert lost(0.0) == set()


def test_a_full_link_drops_and_counts():
    link = EmulatedLink(LinkParams(delay_s=1.0, capacity=8), 1)
    for i in range(10):
        link.send(i * 1e-3, float(i))
    assert link.in_flight == 8 and link.overflowed == 2
    assert link.next_due_s() == 1.0
    assert link.receive(0.5) == -1
    received = []
    while (slot := link.receive(2.0)) >= 0:
        received.append(link.payload(slot)[0])
    assert received == [float(i) for i in range(8)]
    assert link.next_due_s() == math.inf


def test_the_time_is_whatever_the_caller_says():
    """No clock is read: the same sends at times shifted by an hour give the same delays."""
    params = LinkParams(delay_s=0.03, jitter_s=0.003, seed=9)
    a, b = EmulatedLink(params, 1), EmulatedLink(params, 1)
    delays = []
    for link, origin in ((a, 0.0), (b, 3600.0)):
        link.send(origin, 1.0)
        now = origin
        while link.receive(now) < 0:
            now += 1e-4
        delays.append(round(now - origin, 6))
    assert delays[0] == delays[1]


def test_the_link_imports_no_network_engine():
    """The link runs in any process, the virtual clock's included: it must not pull Zenoh in."""
    code = "import sys, hapticop.network.link; print('zenoh' in sys.modules)"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert result.stdout.strip() == "False"


def test_messages_of_any_length_cross_once_in_their_time_and_lost_ones_leave_nothing_behind():
    """A bridge's pings and pongs: bytes of their own lengths, delayed, jittered, lost or duplicated by the link."""
    params = LinkParams(delay_s=0.02, jitter_s=0.005, loss=0.2, duplicate=0.3, seed=5)
    messages = MessageLink(params)
    delivered = []
    for tick in range(600):
        now_ns = tick * 1_000_000
        if tick < 500:
            messages.send(now_ns, b"x" * (tick % 37) + tick.to_bytes(4, "little"))
        while (got := messages.receive(now_ns)) is not None:
            data, sent_ns = got
            index = int.from_bytes(data[-4:], "little")
            assert sent_ns == index * 1_000_000 and len(data) == index % 37 + 4
            assert 0.015 - 1e-9 <= (now_ns - sent_ns) / 1e9 <= 0.025 + 1e-9
            delivered.append(index)
    assert len(delivered) == len(set(delivered))  # a duplicate's copy is not a second message
    link = messages.link
    assert len(delivered) == link.sent - link.lost > 0 and link.lost > 0 and link.duplicated > 0
    assert messages.waiting == 0
