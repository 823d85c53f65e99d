"""Who may drive the console: the checks every HTTP request and websocket passes before a route runs.

In order (the first that fails answers; a websocket is closed with code 1008 and the reason):

1. **Host** (DNS rebinding): the ``Host`` header must name this console — a loopback name
   (``localhost``, ``127.0.0.1``, ``::1``), the ``--host`` it listens on, or an ``--allowed-host``
   (a reverse proxy's name). On a wildcard address (``0.0.0.0``, ``::``) any IP literal is also
   accepted: a rebinding attack needs a domain name. Answer: 421.
2. **Origin**: a page of another origin — or of the opaque origin ``null`` (sandboxed frames,
   ``data:`` and ``file:`` pages) — may not open the websocket nor send anything but GET/HEAD.
   Answer: 403.
3. **CSRF-proof requests**: every request that changes something (not GET/HEAD/OPTIONS) carries a
   JSON body (``Content-Type: application/json``) or the page's ``X-Console-Client`` header; a
   cross-site form or a body-less ``fetch`` from elsewhere can send neither without the browser
   asking this server first (a CORS preflight, which it refuses). Answer: 403.
4. **Token** (when set; at least :data:`MIN_TOKEN_LENGTH` characters): ``?token=`` once (the reply
   sets an HttpOnly cookie and the page then drops it from its address bar), the cookie, or
   ``Authorization: Bearer``. Answer: 401.
5. **Body size**: at most :data:`MAX_BODY_BYTES` per request, by ``Content-Length`` and as it
   streams in (bodies are read whole before a route runs; the API takes only small JSON). Answer: 413.
"""

from __future__ import annotations

import hmac
import ipaddress
from collections.abc import Iterable, MutableMapping
from typing import Any
from urllib.parse import parse_qs, urlsplit

from fastapi.responses import JSONResponse
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from rig.errors import ConfigError

TOKEN_COOKIE = "rig_console_token"
CLIENT_HEADER = "x-console-client"
LOOPBACK_NAMES = ("localhost", "127.0.0.1", "::1")
WILDCARD_HOSTS = ("0.0.0.0", "::", "")
SAFE_METHODS = ("GET", "HEAD", "OPTIONS")
MIN_TOKEN_LENGTH = 16
MAX_BODY_BYTES = 1 << 20  # the largest body the API takes is a few hundred bytes of JSON


class Refused(Exception):
    """A request the access rules refuse: its HTTP status and one line saying why."""

    def __init__(self, status: int, text: str) -> None:
        super().__init__(text)
        self.status = status
        self.text = text


def check_token(token: str | None) -> None:
    """Raise ConfigError unless ``token`` is None (no token) or long enough to guess at no rate."""
    if token is not None and len(token) < MIN_TOKEN_LENGTH:
        raise ConfigError(
            f"--token: expected at least {MIN_TOKEN_LENGTH} characters, found {len(token)}"
            + (" (an empty token would let anyone in)" if not token else "")
        )


def host_name(host_header: str) -> str:
    """The name part of a ``Host`` header: ``[::1]:8765`` -> ``::1``, ``Example.org:80`` -> ``example.org``."""
    host = host_header.strip().lower()
    if host.startswith("["):
        return host[1:].partition("]")[0]
    return host.rpartition(":")[0] if host.count(":") == 1 else host


def _is_ip(name: str) -> bool:
    try:
        ipaddress.ip_address(name)
    except ValueError:
        return False
    return True


class AccessRules:
    """The names this console answers to and its token; :meth:`check` applies rules 1-4."""

    def __init__(self, listen_host: str = "127.0.0.1", allowed_hosts: Iterable[str] = (), token: str | None = None):
        check_token(token)
        self.token = token
        self.any_ip = listen_host in WILDCARD_HOSTS
        self.names = {n.lower() for n in LOOPBACK_NAMES} | {host_name(h) for h in allowed_hosts}
        if not self.any_ip:
            self.names.add(host_name(listen_host) if ":" not in listen_host else listen_host.lower())

    def host_allowed(self, host_header: str) -> bool:
        name = host_name(host_header)
        return name in self.names or (self.any_ip and _is_ip(name))

    def check(self, scope: Scope, headers: dict[str, str]) -> bool:
        """Raise :class:`Refused` if a rule fails; whether the request gave ``?token=`` (set the cookie)."""
        host = headers.get("host", "")
        if not self.host_allowed(host):
            raise Refused(421, f"host {host!r} is not a name of this console (rig console --allowed-host NAME)")
        origin = headers.get("origin")
        changes = scope["type"] == "websocket" or scope.get("method") not in SAFE_METHODS
        if origin is not None and changes and (origin == "null" or urlsplit(origin).netloc.lower() != host.lower()):
            raise Refused(403, f"origin {origin} is not this console")
        if scope["type"] == "http" and changes:
            json_body = headers.get("content-type", "").split(";")[0].strip().lower() == "application/json"
            if not (json_body or headers.get(CLIENT_HEADER)):
                raise Refused(403, f"a request that changes something needs a JSON body or the {CLIENT_HEADER} header")
        if self.token is None:
            return False
        query = parse_qs(scope.get("query_string", b"").decode("latin-1"))
        if not any(hmac.compare_digest(g.encode(), self.token.encode()) for g in _tokens_given(query, headers)):
            raise Refused(401, "access token required: open the URL the console printed")
        return bool(query.get("token"))


def _tokens_given(query: dict[str, list[str]], headers: dict[str, str]) -> list[str]:
    given = list(query.get("token", []))
    for part in headers.get("cookie", "").split(";"):
        key, _, value = part.strip().partition("=")
        if key == TOKEN_COOKIE:
            given.append(value)
    auth = headers.get("authorization", "")
    if auth.lower().startswith("bearer "):
        given.append(auth[7:].strip())
    return given


class AccessMiddleware:
    """ASGI middleware applying :class:`AccessRules` and the body limit to HTTP and websocket requests."""

    def __init__(self, app: ASGIApp, rules: AccessRules, max_body: int = MAX_BODY_BYTES) -> None:
        self.app = app
        self.rules = rules
        self.max_body = max_body

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", [])}
        try:
            set_cookie = self.rules.check(scope, headers)
            if scope["type"] == "http" and int(headers.get("content-length") or 0) > self.max_body:
                raise Refused(413, f"request body: expected at most {self.max_body} bytes")
        except Refused as refused:
            await _refuse(scope, receive, send, refused)
            return
        except ValueError:
            await _refuse(scope, receive, send, Refused(400, "content-length: expected a number"))
            return
        if set_cookie and scope["type"] == "http":
            send = self._with_cookie(send)
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        try:
            body = await self._read_body(receive)
        except Refused as refused:
            await _refuse(scope, receive, send, refused)
            return
        await self.app(scope, _replay(body, receive), send)

    async def _read_body(self, receive: Receive) -> bytes:
        """The whole request body, refused as soon as it grows past the limit (chunked, or a lying length)."""
        parts: list[bytes] = []
        size = 0
        while True:
            message = await receive()
            if message["type"] != "http.request":
                break
            parts.append(message.get("body", b""))
            size += len(parts[-1])
            if size > self.max_body:
                raise Refused(413, f"request body: expected at most {self.max_body} bytes")
            if not message.get("more_body", False):
                break
        return b"".join(parts)

    def _with_cookie(self, send: Send) -> Send:
        cookie = f"{TOKEN_COOKIE}={self.rules.token}; Path=/; HttpOnly; SameSite=Strict".encode("latin-1")

        async def wrapped(message: MutableMapping[str, Any]) -> None:
            if message["type"] == "http.response.start":
                message = {**message, "headers": [*message.get("headers", []), (b"set-cookie", cookie)]}
            await send(message)

        return wrapped


def _replay(body: bytes, receive: Receive) -> Receive:
    """A ``receive`` that gives ``body`` once, then whatever the client sends next (a disconnect)."""
    given = False

    async def replay() -> Message:
        nonlocal given
        if given:
            return await receive()
        given = True
        return {"type": "http.request", "body": body, "more_body": False}

    return replay


async def _refuse(scope: Scope, receive: Receive, send: Send, refused: Refused) -> None:
    if scope["type"] == "websocket":
        await send({"type": "websocket.close", "code": 1008, "reason": refused.text})
        return
    await JSONResponse({"error": refused.text}, status_code=refused.status)(scope, receive, send)
