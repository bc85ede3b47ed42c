"""The recorder's relay to the live view: the messages the recorder already took from DDS,
handed on over a local Unix socket, so the view is not one more DDS reader of the loop's topics.

Each reader of ``/joint_states``, ``/clock`` and the commands costs the plant's and the
controller's writers one more delivery per sample (``bench/live_bench.py``: +12 to 20 % of the
loop's CPU for the view's readers). With a relay, the recorder (which reads every topic for the
bag) sends each message it took, as (DDS receive time, topic, CDR bytes), in the order it
writes them; the view receives them in that order and logs them at the same sim times as the
bag.

Never a wait for the view: the sender is non-blocking; what the socket does not take now stays
queued (:class:`RelaySender`), and past :data:`QUEUED_BYTES` the oldest per-sample messages are
dropped (counted), never the trial results. A view that is not up yet, or went away, loses
nothing but samples beyond the queue: the sender connects again at its next send.

A stream: ``u16`` topic length, topic (UTF-8), ``u64`` receive time (ns), ``u32`` payload
length, payload; little-endian.
"""

from __future__ import annotations

import contextlib
import os
import socket
import struct
from collections import deque
from collections.abc import Collection, Iterable
from pathlib import Path

HEADER = struct.Struct("<H")
BODY = struct.Struct("<QI")
QUEUED_BYTES = 32 * 1024 * 1024
"""Bytes the sender keeps for a view that does not read (then the oldest samples go)."""
CHUNK = 1 << 20
"""Bytes per send and per receive call."""
Message = tuple[int, str, bytes]
"""(DDS receive time ns, topic, CDR bytes)."""


def frame(received: int, topic: str, raw: bytes) -> bytes:
    """One message on the stream."""
    name = topic.encode()
    return b"".join((HEADER.pack(len(name)), name, BODY.pack(received, len(raw)), raw))


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
        received, size = BODY.unpack_from(view, head - BODY.size)
        if len(buffer) < head + size:
            break
        topic = bytes(view[at + HEADER.size:at + HEADER.size + length]).decode()
        out.append((received, topic, bytes(view[head:head + size])))
        at = head + size
    return out, at


class RelaySender:
    """The recorder's side: :meth:`send` never blocks; messages of ``droppable`` topics are
    the ones dropped when the view does not keep up."""

    def __init__(self, path: Path | str, droppable: Collection[str]) -> None:
        self.path = str(path)
        self.droppable = frozenset(droppable)
        self.dropped = 0
        """Messages dropped because the view did not read them (queue full)."""
        self.sent = 0
        self._socket: socket.socket | None = None
        self._queue: deque[tuple[bool, bytes]] = deque()
        self._queued = 0
        self._partial = memoryview(b"")
        """The rest of a message the socket took only in part (sent before anything else)."""

    def send(self, messages: Iterable[Message]) -> None:
        """Queue ``messages`` and send what the socket takes now."""
        for received, topic, raw in messages:
            data = frame(received, topic, raw)
            self._queue.append((topic in self.droppable, data))
            self._queued += len(data)
        self._bound()
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
                    _, data = self._queue.popleft()
                    self._queued -= len(data)
                    self._partial = memoryview(data)
                done = sock.send(self._partial[:CHUNK])
                self._partial = self._partial[done:]
                if not self._partial:
                    self.sent += 1
        except BlockingIOError:
            return
        except OSError:  # the view went away: what it had in part is lost, the rest waits
            self._partial = memoryview(b"")
            self._close()

    def _bound(self) -> None:
        """Drop the oldest droppable messages while the queue holds more than
        :data:`QUEUED_BYTES` (trial results are kept whatever they cost)."""
        if self._queued <= QUEUED_BYTES:
            return
        kept: deque[tuple[bool, bytes]] = deque()
        for droppable, data in self._queue:
            if droppable and self._queued > QUEUED_BYTES:
                self._queued -= len(data)
                self.dropped += 1
            else:
                kept.append((droppable, data))
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

    def close(self) -> None:
        """Try once more to send what is queued, then close."""
        self.flush()
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
