"""Fan-out of session messages to the connected pages (websocket clients).

:meth:`Hub.publish` is called from any thread; delivery happens on the event loop. Live frames are
dropped for a page that has not yet taken the previous one (a slow page never holds up the rig);
every other message is queued (up to a bound, beyond which a stuck page loses messages, not memory).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from typing import Any

from fastapi import WebSocket

QUEUE_BOUND = 512
Message = tuple[dict[str, Any], bytes | None]


class Hub:
    """Delivers session messages to every connected page."""

    def __init__(self) -> None:
        self.loop: asyncio.AbstractEventLoop | None = None
        self.clients: dict[str, asyncio.Queue[Message]] = {}
        self.frame_pending: dict[str, bool] = {}

    def publish(self, message: dict[str, Any], image: bytes | None = None) -> None:
        """Thread-safe: queue ``message`` (and its image) for every client."""
        loop = self.loop
        if loop is None or loop.is_closed():
            return
        with contextlib.suppress(RuntimeError):  # the loop is shutting down
            loop.call_soon_threadsafe(self._deliver, message, image)

    def _deliver(self, message: dict[str, Any], image: bytes | None) -> None:
        for client, q in self.clients.items():
            if image is not None:
                if self.frame_pending.get(client):
                    continue
                self.frame_pending[client] = True
            with contextlib.suppress(asyncio.QueueFull):
                q.put_nowait((message, image))

    def join(self, client: str) -> asyncio.Queue[Message]:
        """Register a page (event-loop thread); its queue."""
        q: asyncio.Queue[Message] = asyncio.Queue(maxsize=QUEUE_BOUND)
        self.clients[client] = q
        return q

    def leave(self, client: str) -> None:
        self.clients.pop(client, None)
        self.frame_pending.pop(client, None)

    async def forward(self, client: str, q: asyncio.Queue[Message], socket: WebSocket) -> None:
        """Send what is queued for ``client`` over its websocket: text, or a framed live image."""
        while True:
            message, image = await q.get()
            if image is None:
                await socket.send_text(json.dumps(message, default=str))
                continue
            header = json.dumps(message).encode()
            await socket.send_bytes(len(header).to_bytes(4, "little") + header + image)
            self.frame_pending[client] = False
