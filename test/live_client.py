"""A headless Foxglove WebSocket client (Python ``websockets``), for the live view's test and
bench: connects with subprotocol ``foxglove.sdk.v1``, subscribes to every channel the server
advertises, and keeps every message with its channel (schema, encoding) as advertised."""

from __future__ import annotations

import asyncio
import json
import struct
import time
from dataclasses import dataclass, field
from typing import Any

import websockets

SUBPROTOCOL = "foxglove.sdk.v1"


@dataclass
class Received:
    """What a client got: the channels advertised (by id) and per topic the
    (log time, payload) messages, plus the server's time broadcasts."""

    channels: dict[int, dict[str, Any]] = field(default_factory=dict)
    messages: dict[str, list[tuple[int, bytes]]] = field(default_factory=dict)
    times: list[int] = field(default_factory=list)
    server_info: dict[str, Any] = field(default_factory=dict)
    first_subscribed: float | None = None


async def _collect(url: str, received: Received, connect_timeout: float,
                   duration: float | None) -> None:
    deadline = time.monotonic() + connect_timeout
    while True:
        try:
            ws = await websockets.connect(url, subprotocols=[SUBPROTOCOL],  # type: ignore[list-item]
                                          max_size=None)
            break
        except (OSError, websockets.exceptions.InvalidHandshake):
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.05)
    by_subscription: dict[int, str] = {}
    end = None if duration is None else time.monotonic() + duration
    async with ws:
        while True:
            timeout = None if end is None else max(0.0, end - time.monotonic())
            try:
                frame = await asyncio.wait_for(ws.recv(), timeout)
            except (websockets.exceptions.ConnectionClosed, TimeoutError):
                return
            if isinstance(frame, str):
                message = json.loads(frame)
                if message.get("op") == "serverInfo":
                    received.server_info = message
                elif message.get("op") == "advertise":
                    subscriptions = []
                    for channel in message["channels"]:
                        received.channels[channel["id"]] = channel
                        sub_id = len(by_subscription) + 1
                        by_subscription[sub_id] = channel["topic"]
                        received.messages.setdefault(channel["topic"], [])
                        subscriptions.append({"id": sub_id, "channelId": channel["id"]})
                    await ws.send(json.dumps({"op": "subscribe",
                                              "subscriptions": subscriptions}))
                    if received.first_subscribed is None:
                        received.first_subscribed = time.monotonic()
            elif frame[0] == 0x01:
                sub_id, log_time = struct.unpack_from("<IQ", frame, 1)
                received.messages[by_subscription[sub_id]].append((log_time, bytes(frame[13:])))
            elif frame[0] == 0x02:
                received.times.append(struct.unpack_from("<Q", frame, 1)[0])


def collect(url: str, connect_timeout: float = 60.0, duration: float | None = None,
            received: Received | None = None) -> Received:
    """Connect (retrying until ``connect_timeout``), subscribe to everything, and collect
    until the server closes the connection (or ``duration`` s)."""
    out = received if received is not None else Received()
    asyncio.run(_collect(url, out, connect_timeout, duration))
    return out


def main() -> None:
    """``python test/live_client.py ws://127.0.0.1:8765``: collect until the server closes,
    then print the messages per topic as JSON (the live bench's client process)."""
    import sys

    received = collect(sys.argv[1], float(sys.argv[2]) if len(sys.argv) > 2 else 120.0)
    counts: dict[str, float] = {topic: len(m) for topic, m in received.messages.items()}
    counts["cpu_seconds"] = time.process_time()
    print(json.dumps(counts), flush=True)


if __name__ == "__main__":
    main()
