"""How the console is served: uvicorn with timeouts that a slow or idle client cannot outlast.

uvicorn closes a keep-alive connection that stays idle, but waits forever for the headers of a
request that trickles in a byte at a time (slowloris): :class:`HeaderDeadlineProtocol` gives every
request's headers :data:`HEADER_TIMEOUT_S` from the moment the connection opened (or the previous
response ended), then closes the connection.
"""

from __future__ import annotations

import asyncio
from typing import Any

import h11
import uvicorn
from uvicorn.protocols.http.h11_impl import H11Protocol

HEADER_TIMEOUT_S = 10.0
IDLE_TIMEOUT_S = 5.0  # keep-alive connections with no request


class HeaderDeadlineProtocol(H11Protocol):
    """uvicorn's h11 protocol with a deadline for each request's headers."""

    header_timeout_s = HEADER_TIMEOUT_S

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._arm_header_deadline()

    def on_response_complete(self) -> None:
        super().on_response_complete()
        self._arm_header_deadline()

    _armed = 0  # which deadline is the current one

    def _arm_header_deadline(self) -> None:
        self._armed += 1
        self.loop.call_later(self.header_timeout_s, self._header_deadline, self._armed)

    def _header_deadline(self, armed: int) -> None:
        """Close the connection if it still waits for the headers the deadline ``armed`` was set for."""
        waiting = self.conn.their_state is h11.IDLE and (self.cycle is None or self.cycle.response_complete)
        if armed == self._armed and waiting and not self.transport.is_closing():
            self.transport.close()


def server_config(app: Any, host: str, port: int, header_timeout_s: float = HEADER_TIMEOUT_S) -> uvicorn.Config:
    """The uvicorn configuration the console runs with (``rig console`` and the browser tests)."""
    protocol = type("ConsoleHttp", (HeaderDeadlineProtocol,), {"header_timeout_s": header_timeout_s})
    return uvicorn.Config(
        app,
        host=host,
        port=port,
        log_level="warning",
        ws="websockets-sansio",
        http=protocol,
        timeout_keep_alive=int(IDLE_TIMEOUT_S),
        h11_max_incomplete_event_size=64 * 1024,
    )
