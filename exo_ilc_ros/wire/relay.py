"""The recorder's relay to the live view: the messages the recorder already took from DDS,
handed on over a local Unix socket, so the view is not one more DDS reader of the loop's topics,
at the display rate (:class:`SampleGate`).

Each reader of ``/joint_states``, ``/clock`` and the commands costs the plant's and the
controller's writers one more delivery per sample (``bench/live_bench.py``: +12 to 20 % of the
loop's CPU for the view's readers). With a relay, the recorder (which reads every topic for the
bag) sends each message it took, as (log time, topic, CDR bytes), in the order it writes them;
the view receives them in that order and logs them at the bag's log times.

Never a wait for the view: the sender is non-blocking; what the socket does not take now stays
queued (:class:`RelaySender`), and past :data:`QUEUED_BYTES` the oldest per-sample messages are
dropped (counted), never the trial results. A view that is not up yet, or went away, loses
nothing but samples beyond the queue: the sender connects again at its next send.

A stream: ``u16`` topic length, topic (UTF-8), ``u64`` log time (ns), ``u32`` payload length,
payload; little-endian.
"""

from __future__ import annotations

import contextlib
import os
import socket
import struct
import time
from collections import deque
from collections.abc import Collection, Iterable
from pathlib import Path

HEADER = struct.Struct("<H")
BODY = struct.Struct("<QI")
QUEUED_BYTES = 32 * 1024 * 1024
"""Bytes the sender keeps for a view that does not read (then the oldest samples go)."""
DISPLAY_RATE = 200.0
"""Per-sample messages per second of wall time the live view shows by default (each of
/joint_states, the commands, /clock): every sample of a real-time loop up to 200 Hz."""
CHUNK = 1 << 20
"""Bytes per send and per receive call."""
Message = tuple[int, str, bytes]
"""(time ns, topic, CDR bytes): the bag's log time on the stream."""


_HEADS: dict[str, bytes] = {}
"""Each topic's framed name (``u16`` length, UTF-8)."""


def frame(time_ns: int, topic: str, raw: bytes) -> bytes:
    """One message on the stream."""
    return b"".join(_frame_parts(time_ns, topic, raw))


def _frame_parts(time_ns: int, topic: str, raw: bytes) -> tuple[bytes, bytes, bytes]:
    head = _HEADS.get(topic)
    if head is None:
        name = topic.encode()
        head = _HEADS[topic] = HEADER.pack(len(name)) + name
    return head, BODY.pack(time_ns, len(raw)), raw


def unframe(buffer: bytes | bytearray) -> tuple[list[Message], int]:
    """The whole messages at the start of ``buffer`` and how many bytes they used."""
    out: list[Message] = []
    at = 0
    view = memoryview(buffer)
    while len(buffer) - at >= HEADER.size:
        (length,) = HEADER.unpack_from(view, at)
        head = at + HEADER.size + length + BODY.size
        if len(buffer) < head:
            break
        time_ns, size = BODY.unpack_from(view, head - BODY.size)
        if len(buffer) < head + size:
            break
        topic = bytes(view[at + HEADER.size:at + HEADER.size + length]).decode()
        out.append((time_ns, topic, bytes(view[head:head + size])))
        at = head + size
    return out, at


class SampleGate:
    """The live view's display rate: of each per-sample topic (``per_sample``), a message only
    if ``1 / rate`` s of wall time passed since the last one let through (``rate`` 0: every
    one). The other topics always pass. At the loop's own pace (a real arm at 100 Hz) a rate
    above it shows every sample; a lock-step simulation running far faster than real time is
    shown at ``rate`` samples per second, so the view's cost does not grow with the graph's
    speed (``bench/live_bench.py``)."""

    def __init__(self, rate: float, per_sample: Collection[str]) -> None:
        if not rate >= 0.0:
            raise ValueError(f"a display rate is >= 0 samples/s (0: every sample), not {rate!r}")
        self.spacing = int(1e9 / rate) if rate > 0.0 else 0
        self.per_sample = frozenset(per_sample)
        self._next: dict[str, int] = {}

    def admit(self, topic: str, wall_ns: int) -> bool:
        """Whether ``topic``'s message received at ``wall_ns`` (wall clock, ns) is shown."""
        if not self.spacing or topic not in self.per_sample:
            return True
        if wall_ns < self._next.get(topic, 0):
            return False
        self._next[topic] = wall_ns + self.spacing
        return True


class RelaySender:
    """The recorder's side: :meth:`send` never blocks; messages of ``droppable`` topics are
    the ones dropped when the view does not keep up. The messages of one :meth:`send` go
    out as one buffer (one ``send`` call, not one per message), cut only where droppable
    messages meet kept ones."""

    def __init__(self, path: Path | str, droppable: Collection[str]) -> None:
        self.path = str(path)
        self.droppable = frozenset(droppable)
        self.dropped = 0
        """Messages dropped because the view did not read them (queue full), or went away
        while it had them in part."""
        self.sent = 0
        self._socket: socket.socket | None = None
        self._queue: deque[tuple[bool, int, bytes]] = deque()
        """Runs of framed messages: (droppable, how many, bytes)."""
        self._queued = 0
        self._partial = memoryview(b"")
        """The rest of a run the socket took only in part (sent before anything else)."""
        self._partial_count = 0

    def send(self, messages: Iterable[Message]) -> None:
        """Queue ``messages`` and send what the socket takes now."""
        parts: list[bytes] = []
        count = 0
        run_droppable = True
        droppable, queue = self.droppable, self._queue
        for time_ns, topic, raw in messages:
            kind = topic in droppable
            if kind != run_droppable and count:
                data = b"".join(parts)
                queue.append((run_droppable, count, data))
                self._queued += len(data)
                parts, count = [], 0
            run_droppable = kind
            parts.extend(_frame_parts(time_ns, topic, raw))
            count += 1
        if count:
            data = b"".join(parts)
            queue.append((run_droppable, count, data))
            self._queued += len(data)
            self._bound()
        if queue or self._partial:
            self.flush()

    def flush(self) -> None:
        """Send what the socket takes now (connect first if needed)."""
        if self._socket is None and not self._connect():
            return
        sock = self._socket
        assert sock is not None
        try:
            while self._partial or self._queue:
                if not self._partial:
                    _, count, data = self._queue.popleft()
                    self._queued -= len(data)
                    self._partial, self._partial_count = memoryview(data), count
                done = sock.send(self._partial[:CHUNK])
                self._partial = self._partial[done:]
                if not self._partial:
                    self.sent += self._partial_count
        except BlockingIOError:
            return
        except OSError:  # the view went away: the run it had in part is lost, the rest waits
            self.dropped += self._partial_count
            self._partial, self._partial_count = memoryview(b""), 0
            self._close()

    def _bound(self) -> None:
        """Drop the oldest droppable runs while the queue holds more than
        :data:`QUEUED_BYTES` (trial results are kept whatever they cost)."""
        if self._queued <= QUEUED_BYTES:
            return
        kept: deque[tuple[bool, int, bytes]] = deque()
        for droppable, count, data in self._queue:
            if droppable and self._queued > QUEUED_BYTES:
                self._queued -= len(data)
                self.dropped += count
            else:
                kept.append((droppable, count, data))
        self._queue = kept

    def _connect(self) -> bool:
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        sock.setblocking(False)
        try:
            sock.connect(self.path)
        except OSError:  # no view listening (yet): the recording never fails for the view
            sock.close()
            return False
        self._socket = sock
        return True

    def _close(self) -> None:
        if self._socket is not None:
            self._socket.close()
            self._socket = None

    def close(self, timeout: float = 2.0) -> None:
        """Send what is queued (for at most ``timeout`` s: the run is over, the loop waits for
        nothing), then close."""
        deadline = time.monotonic() + timeout
        self.flush()
        while (self._queue or self._partial) and self._socket is not None \
                and time.monotonic() < deadline:
            time.sleep(0.001)
            self.flush()
        self.dropped += sum(count for _, count, _ in self._queue)
        self._queue.clear()
        self._close()


class RelayReceiver:
    """The view's side: listens at ``path``; :meth:`take` returns what arrived, never waits."""

    def __init__(self, path: Path | str) -> None:
        self.path = str(path)
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.path)
        self._listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self._listener.bind(self.path)
        self._listener.listen(4)
        self._listener.setblocking(False)
        self._peers: list[tuple[socket.socket, bytearray]] = []

    @property
    def finished(self) -> bool:
        """No sender is connected: every one that came has closed (the recorder's last message
        is in), or none came (nothing to wait for)."""
        return not self._peers

    def take(self) -> list[Message]:
        """Every whole message received so far, in the order each sender sent them."""
        with contextlib.suppress(BlockingIOError):
            while True:
                peer, _ = self._listener.accept()
                peer.setblocking(False)
                self._peers.append((peer, bytearray()))
        out: list[Message] = []
        open_peers = []
        for peer, buffer in self._peers:
            closed = False
            while True:
                try:
                    data = peer.recv(CHUNK)
                except BlockingIOError:
                    break
                if not data:
                    closed = True
                    break
                buffer += data
            messages, used = unframe(buffer)
            del buffer[:used]
            out.extend(messages)
            if closed:
                peer.close()
            else:
                open_peers.append((peer, buffer))
        self._peers = open_peers
        return out

    def close(self) -> None:
        """Stop listening and remove the socket file."""
        for peer, _ in self._peers:
            peer.close()
        self._peers.clear()
        self._listener.close()
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.path)
