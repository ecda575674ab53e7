"""A small HTTP/1.1 client for the lasertag server: one persistent keep-alive connection.

An environment step is one request, so what a request costs on the client is what a step
costs. Each request is written with one ``sendall`` (request line, headers and body
together) and the answer is read by its ``Content-Length`` from a buffered socket.

Why not ``http.client``: it writes the header and the body in two system calls (two wake-ups
of the server's reader per request) and parses every answer's headers with the ``email``
package. Measured on the 2-core machine, a step's client CPU time was about twice this
client's (docs/research.md, "Where the time goes"). ``requests`` adds more on top. The
server's answers are small JSON documents with a length, which is all this client reads
(chunked answers are read too, for a proxy in between).
"""

from __future__ import annotations

import json
import os
import socket
import time
from typing import Any
from urllib.parse import urlsplit

try:  # orjson parses the observations several times faster; it is optional.
    import orjson

    loads = orjson.loads
except ImportError:  # pragma: no cover - depends on what is installed
    loads = json.loads

__all__ = ["Client", "ServerError", "ConnectionDropped", "loads"]

# The server closes a keep-alive connection that sits idle for its header read timeout
# (10 s by default). Reconnecting before sending after a shorter pause means a request is
# almost never written to a socket the server is about to close.
_IDLE_RECONNECT_S = 5.0
_MAX_LINE = 65536


class ServerError(RuntimeError):
    """The server answered with an error status; ``status`` and ``message`` say which."""

    def __init__(self, method: str, path: str, status: int, message: str):
        super().__init__(f"{method} {path}: {status} {message}")
        self.status = status
        self.message = message


class ConnectionDropped(ConnectionError):
    """The connection closed before any byte of the answer arrived."""


class Response:
    __slots__ = ("status", "headers", "body")

    def __init__(self, status: int, headers: dict[str, str], body: bytes):
        self.status = status
        self.headers = headers
        self.body = body


class Client:
    """Requests to one server over one connection; ``token`` is sent as a Bearer token."""

    def __init__(self, url: str, token: str | None = None, timeout: float = 120.0):
        parts = urlsplit(url if "://" in url else "http://" + url)
        if parts.scheme != "http":
            raise ValueError(f"server {url!r}: only http:// URLs are supported")
        if not parts.hostname:
            raise ValueError(f"server {url!r}: no host")
        self.host = parts.hostname
        self.port = parts.port or 80
        host = f"[{self.host}]" if ":" in self.host else self.host
        self.url = f"http://{host}:{self.port}"
        self.timeout = timeout
        self.token = token
        self._host_header = f"Host: {host}:{self.port}\r\n"
        self._sock: socket.socket | None = None
        self._rfile = None
        self._last = 0.0
        self._pid = os.getpid()

    def _connect(self) -> None:
        now = time.monotonic()
        if self._sock is not None and self._pid != os.getpid():
            # A forked child must not read answers meant for its parent on a shared socket.
            self._sock = self._rfile = None
        if self._sock is not None and now - self._last > _IDLE_RECONNECT_S:
            self.close()
        if self._sock is None:
            sock = socket.create_connection((self.host, self.port), self.timeout)
            # Requests are small and answered before the next: waiting to coalesce them
            # (Nagle) would only add latency.
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._sock = sock
            self._rfile = sock.makefile("rb")
            self._pid = os.getpid()

    def close(self) -> None:
        if self._rfile is not None:
            self._rfile.close()
            self._rfile = None
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def raw(self, method: str, path: str, body: bytes | None = None,
            token: str | None = None) -> Response:
        """One request and its answer. Retries only what the server did not apply.

        A request is sent again only when the connection closed before any byte of the
        answer (the server closes idle keep-alive connections, and a request caught in that
        race is never read), or when the server answered 429 (refused, so not applied): an
        ``act`` is never applied twice.
        """
        token = token or self.token
        head = f"{method} {path} HTTP/1.1\r\n{self._host_header}"
        if token:
            head += f"Authorization: Bearer {token}\r\n"
        if body is not None:
            head += f"Content-Type: application/json\r\nContent-Length: {len(body)}\r\n\r\n"
            request = head.encode() + body
        else:
            request = (head + "\r\n").encode()
        dropped = refused = 0
        while True:
            self._connect()
            try:
                try:
                    self._sock.sendall(request)
                except (BrokenPipeError, ConnectionResetError) as e:
                    raise ConnectionDropped(str(e)) from e
                resp = self._read(method)
            except ConnectionDropped:
                self.close()
                dropped += 1
                if dropped > 1:
                    raise
                continue
            except BaseException:
                # A time-out or an interrupted read leaves the connection mid-answer.
                self.close()
                raise
            self._last = time.monotonic()
            if resp.headers.get("connection", "").lower() == "close":
                self.close()
            retry_after = resp.headers.get("retry-after")
            if resp.status == 429 and retry_after is not None and refused < 30:
                # Past the per-address request rate (a server used without the admin
                # token; a quota refusal has no Retry-After and is the caller's): the
                # request was refused, not applied, so waiting and sending it again is safe.
                refused += 1
                try:
                    wait = float(retry_after)
                except ValueError:
                    wait = 1.0
                time.sleep(min(max(wait, 0.05), 5.0))
                continue
            return resp

    def _read(self, method: str) -> Response:
        f = self._rfile
        try:
            line = f.readline(_MAX_LINE)
        except ConnectionResetError as e:
            raise ConnectionDropped(str(e)) from e
        if not line:
            raise ConnectionDropped(f"{self.url} closed the connection before answering")
        try:
            status = int(line.split(None, 2)[1])
        except (IndexError, ValueError):
            raise ConnectionError(f"{self.url}: not an HTTP answer: {line[:80]!r}") from None
        headers: dict[str, str] = {}
        while True:
            h = f.readline(_MAX_LINE)
            if h in (b"\r\n", b"\n"):
                break
            if not h:
                raise ConnectionError(f"{self.url} closed the connection mid-answer")
            name, _, value = h.decode("latin-1").partition(":")
            headers[name.strip().lower()] = value.strip()
        if method == "HEAD" or status in (204, 304) or 100 <= status < 200:
            return Response(status, headers, b"")
        if "chunked" in headers.get("transfer-encoding", "").lower():
            return Response(status, headers, self._read_chunked())
        length = headers.get("content-length")
        if length is None:
            body = f.read()  # delimited by the end of the connection
            headers["connection"] = "close"
        else:
            n = int(length)
            body = f.read(n)
            if len(body) != n:
                raise ConnectionError(f"{self.url} closed the connection mid-answer")
        return Response(status, headers, body)

    def _read_chunked(self) -> bytes:
        f = self._rfile
        parts = []
        while True:
            size = int(f.readline(_MAX_LINE).split(b";", 1)[0].strip() or b"0", 16)
            if size == 0:
                while f.readline(_MAX_LINE) not in (b"\r\n", b"\n", b""):
                    pass  # trailers
                return b"".join(parts)
            parts.append(f.read(size))
            f.readline(_MAX_LINE)

    def call(self, method: str, path: str, payload: Any = None,
             token: str | None = None) -> Any:
        """A request whose answer is JSON (or empty); error statuses raise ServerError."""
        body = None if payload is None else json.dumps(payload).encode()
        resp = self.raw(method, path, body, token)
        if resp.status >= 400:
            raise ServerError(method, path, resp.status, error_message(resp.body))
        return loads(resp.body) if resp.body else None


def error_message(data: bytes) -> str:
    """The ``error`` of an error answer's body, or the body itself."""
    try:
        return str(loads(data)["error"])
    except Exception:
        return data[:500].decode("utf-8", "replace")
