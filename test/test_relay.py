"""The recorder's relay to the live view (wire/relay.py): order, whole messages, nothing
waits, the oldest samples dropped (never the trial results) when the view does not read."""

from __future__ import annotations

from pathlib import Path

import pytest

from exo_ilc_ros.wire import relay
from exo_ilc_ros.wire.relay import RelayReceiver, RelaySender, frame, unframe

SAMPLE = "/joint_states"
RESULT = "/ilc/trial_summary"


def test_frames_split_anywhere_come_back_whole_and_in_order() -> None:
    messages = [(i, SAMPLE if i % 3 else RESULT, bytes([i % 256]) * (i * 7)) for i in range(50)]
    stream = b"".join(frame(*m) for m in messages)
    out: list[tuple[int, str, bytes]] = []
    buffer = bytearray()
    for at in range(0, len(stream), 97):  # arbitrary cuts, mid-header and mid-payload
        buffer += stream[at:at + 97]
        got, used = unframe(buffer)
        del buffer[:used]
        out.extend(got)
    assert out == messages and not buffer


def test_sender_queues_until_the_view_listens_then_delivers_in_order(tmp_path: Path) -> None:
    path = tmp_path / "relay.sock"
    sender = RelaySender(path, {SAMPLE})
    sender.send([(1, SAMPLE, b"a"), (2, RESULT, b"b")])  # nobody listens: kept, no error
    receiver = RelayReceiver(path)
    sender.send([(3, SAMPLE, b"c" * 300_000)])  # more than one send call takes
    got: list[tuple[int, str, bytes]] = []
    for _ in range(100):
        got += receiver.take()
        sender.flush()
        if len(got) == 3:
            break
    assert [(r, t) for r, t, _ in got] == [(1, SAMPLE), (2, RESULT), (3, SAMPLE)]
    assert got[2][2] == b"c" * 300_000 and sender.dropped == 0
    sender.close()
    receiver.close()
    assert not path.exists()


def test_one_send_goes_out_as_runs_cut_only_between_samples_and_results(
        tmp_path: Path) -> None:
    """What the recorder hands on per drain is framed into one buffer per run of samples or
    of results (one socket send each, not one per message), and arrives whole and in order."""
    path = tmp_path / "relay.sock"
    sender = RelaySender(path, {SAMPLE})
    batch = [(i, RESULT if i in (3, 4) else SAMPLE, bytes([i]) * i) for i in range(10)]
    sender.send(batch)  # nobody listens yet: queued
    assert [(droppable, count) for droppable, count, _ in sender._queue] == [
        (True, 3), (False, 2), (True, 5)]
    receiver = RelayReceiver(path)
    got: list[tuple[int, str, bytes]] = []
    for _ in range(100):
        sender.flush()
        got += receiver.take()
        if len(got) == len(batch):
            break
    assert got == batch and sender.sent == len(batch) and sender.dropped == 0
    sender.close()
    receiver.close()


def test_a_view_that_does_not_read_loses_old_samples_never_results(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(relay, "QUEUED_BYTES", 10_000)
    path = tmp_path / "relay.sock"
    receiver = RelayReceiver(path)  # listens, never reads until the end
    sender = RelaySender(path, {SAMPLE})
    payload = b"x" * 1000
    for i in range(2000):  # ~2 MB: beyond what the socket and the queue hold
        sender.send([(i, RESULT if i % 100 == 0 else SAMPLE, payload)])
    assert sender.dropped > 0
    got: list[tuple[int, str, bytes]] = []
    for _ in range(1000):
        got += receiver.take()
        sender.flush()
        if not sender._queue and not sender._partial:
            break
    got += receiver.take()
    assert sorted(r for r, t, _ in got if t == RESULT) == list(range(0, 2000, 100))
    times = [r for r, _, _ in got]
    assert times == sorted(times)  # what arrives is in order
    assert len(got) + sender.dropped == 2000  # each one either arrived or was counted dropped
    sender.close()
    receiver.close()


def test_a_view_that_restarts_gets_what_came_after(tmp_path: Path) -> None:
    path = tmp_path / "relay.sock"
    receiver = RelayReceiver(path)
    sender = RelaySender(path, {SAMPLE})
    sender.send([(1, RESULT, b"one")])
    assert [m[0] for m in receiver.take()] == [1]
    receiver.close()  # the view went away
    sender.send([(2, SAMPLE, b"lost or kept")])
    sender.send([(3, SAMPLE, b"x")])
    receiver = RelayReceiver(path)
    sender.send([(4, RESULT, b"four")])
    got = []
    for _ in range(50):
        got += receiver.take()
        sender.flush()
    assert got and got[-1][0] == 4 and all(t in (SAMPLE, RESULT) for _, t, _ in got)
    sender.close()
    receiver.close()


def test_the_display_rate_thins_the_samples_only() -> None:
    """SampleGate: at 200/s, samples 1 ms apart (a lock-step run) are shown every 5 ms; 10 ms
    apart (a real-time 100 Hz loop) every one; the trial results always; 0: every sample."""
    gate = relay.SampleGate(200.0, {SAMPLE})
    fast = [gate.admit(SAMPLE, i * 1_000_000) for i in range(100)]
    assert sum(fast) == 20 and fast[0] and fast[5] and not any(fast[1:5])
    assert all(gate.admit(RESULT, i) for i in range(100))
    slow = relay.SampleGate(200.0, {SAMPLE})
    assert all(slow.admit(SAMPLE, i * 10_000_000) for i in range(100))
    every = relay.SampleGate(0.0, {SAMPLE})
    assert all(every.admit(SAMPLE, i) for i in range(100))
    with pytest.raises(ValueError, match=">= 0"):
        relay.SampleGate(-1.0, {SAMPLE})
