"""A small HTTP/1.1 client for the lasertag server: one persistent keep-alive connection.

An environment step is one request, so what a request costs on the client is what a step
costs. Each request is written with one ``sendall`` (request line, headers and body
together) and the answer is read by its ``Content-Length`` into a buffer of the client's
own: usually one ``recv`` an answer. The socket is a blocking one with the kernel's own
send and receive time-outs (``SO_SNDTIMEO``, ``SO_RCVTIMEO``) where the platform has them:
a Python socket time-out would add a ``poll`` before every send and every receive.

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
import struct
import sys
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
# How long a request waits for a restarting server to be back (it resumes its matches within
# seconds; docs/operations.md).
_RESTART_WAIT_S = 30.0


def _wait_out(retry_after: str) -> None:
    """Sleeps for what a ``Retry-After`` of seconds says (0.05 to 5 s)."""
    try:
        wait = float(retry_after)
    except ValueError:
        wait = 1.0
    time.sleep(min(max(wait, 0.05), 5.0))
_MAX_HEAD = 65536
_RECV = 65536

# This process's id, kept by a fork hook rather than asked of the kernel every request.
_pid = [os.getpid()]
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=lambda: _pid.__setitem__(0, os.getpid()))


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
        # Request heads (request line, host, token) by method, path and token: an
        # environment sends the same one every step.
        self._heads: dict[tuple, bytes] = {}
        self._sock: socket.socket | None = None
        self._buf = bytearray()  # what was received and not yet read
        self._last = 0.0
        self._pid = _pid[0]
        # Whether a server answered here once (a refused connection then means a restart).
        self._was_up = False

    def _connect(self) -> None:
        now = time.monotonic()
        if self._sock is not None and self._pid != _pid[0]:
            # A forked child must not read answers meant for its parent on a shared socket.
            self._sock = None
            self._buf = bytearray()
        if self._sock is not None and now - self._last > _IDLE_RECONNECT_S:
            self.close()
        if self._sock is None:
            sock = socket.create_connection((self.host, self.port), self.timeout)
            # Requests are small and answered before the next: waiting to coalesce them
            # (Nagle) would only add latency.
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            _kernel_timeouts(sock, self.timeout)
            self._sock = sock
            self._buf = bytearray()
            self._pid = _pid[0]
            self._was_up = True

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None
        self._buf = bytearray()

    def raw(self, method: str, path: str, body: bytes | None = None,
            token: str | None = None) -> Response:
        """One request and its answer. Retries only what the server did not apply.

        A request is sent again only when the connection closed before any byte of the
        answer (the server closes idle keep-alive connections, and a request caught in that
        race is never read), when the server answered 429 (refused, so not applied), or
        when a restarting server is not there yet or answers 503 with ``Retry-After`` while
        it resumes the match (docs/api.md): an ``act`` is never applied twice. A restart is
        waited for up to ``_RESTART_WAIT_S``.
        """
        token = token or self.token
        head = self._heads.get((method, path, token))
        if head is None:
            text = f"{method} {path} HTTP/1.1\r\n{self._host_header}"
            if token:
                text += f"Authorization: Bearer {token}\r\n"
            head = text.encode()
            if len(self._heads) > 64:
                self._heads.clear()
            self._heads[(method, path, token)] = head
        if body is not None:
            request = b"%sContent-Type: application/json\r\nContent-Length: %d\r\n\r\n%s" % (
                head, len(body), body,
            )
        else:
            request = head + b"\r\n"
        dropped = refused = 0
        restart_deadline = None
        while True:
            try:
                self._connect()
            except ConnectionRefusedError:
                # Nobody listens where a server did: one restarting (it resumes its
                # matches). Try again for a while; nothing was sent.
                if not self._was_up:
                    raise
                now = time.monotonic()
                restart_deadline = restart_deadline or now + _RESTART_WAIT_S
                if now >= restart_deadline:
                    raise
                time.sleep(0.25)
                continue
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
                _wait_out(retry_after)
                continue
            if resp.status == 503 and retry_after is not None:
                # A match being resumed after a restart: refused, not applied.
                now = time.monotonic()
                restart_deadline = restart_deadline or now + _RESTART_WAIT_S
                if now < restart_deadline:
                    _wait_out(retry_after)
                    continue
            return resp

    def _more(self) -> int:
        """Receives what has arrived (waiting for something) into the buffer; 0 at the end
        of the connection."""
        try:
            chunk = self._sock.recv(_RECV)
        except BlockingIOError:  # SO_RCVTIMEO ran out
            raise socket.timeout(f"{self.url} did not answer within {self.timeout} s") from None
        self._buf += chunk
        return len(chunk)

    def _read(self, method: str) -> Response:
        buf = self._buf
        try:
            while (end := buf.find(b"\r\n\r\n")) < 0:
                if len(buf) > _MAX_HEAD:
                    raise ConnectionError(f"{self.url}: an answer's head is too long")
                if not self._more():
                    if buf:
                        raise ConnectionError(f"{self.url} closed the connection mid-answer")
                    raise ConnectionDropped(f"{self.url} closed the connection before answering")
        except ConnectionResetError as e:
            if buf:
                raise ConnectionError(f"{self.url} reset the connection mid-answer") from e
            raise ConnectionDropped(str(e)) from e
        lines = buf[:end].decode("latin-1").split("\r\n")
        del buf[: end + 4]
        try:
            status = int(lines[0].split(None, 2)[1])
        except (IndexError, ValueError):
            raise ConnectionError(f"{self.url}: not an HTTP answer: {lines[0][:80]!r}") from None
        headers: dict[str, str] = {}
        for h in lines[1:]:
            name, _, value = h.partition(":")
            headers[name.strip().lower()] = value.strip()
        if method == "HEAD" or status in (204, 304) or 100 <= status < 200:
            return Response(status, headers, b"")
        if "chunked" in headers.get("transfer-encoding", "").lower():
            return Response(status, headers, self._read_chunked())
        length = headers.get("content-length")
        if length is None:
            while self._more():  # delimited by the end of the connection
                pass
            headers["connection"] = "close"
            n = len(buf)
        else:
            n = int(length)
            while len(buf) < n:
                if not self._more():
                    raise ConnectionError(f"{self.url} closed the connection mid-answer")
        body = bytes(buf[:n])
        del buf[:n]
        return Response(status, headers, body)

    def _line(self) -> bytes:
        buf = self._buf
        while (end := buf.find(b"\r\n")) < 0:
            if len(buf) > _MAX_HEAD or not self._more():
                raise ConnectionError(f"{self.url}: a broken chunked answer")
        line = bytes(buf[:end])
        del buf[: end + 2]
        return line

    def _exactly(self, n: int) -> bytes:
        buf = self._buf
        while len(buf) < n:
            if not self._more():
                raise ConnectionError(f"{self.url} closed the connection mid-answer")
        data = bytes(buf[:n])
        del buf[:n]
        return data

    def _read_chunked(self) -> bytes:
        parts = []
        while True:
            size = int(self._line().split(b";", 1)[0].strip() or b"0", 16)
            if size == 0:
                while self._line():
                    pass  # trailers
                return b"".join(parts)
            parts.append(self._exactly(size))
            self._line()

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


def _kernel_timeouts(sock: socket.socket, timeout: float) -> None:
    """Makes ``sock`` blocking with the kernel's send and receive time-outs, where the
    platform takes them as a ``struct timeval`` (Linux, the BSDs, macOS); elsewhere it
    keeps Python's time-out."""
    if not sys.platform.startswith(("linux", "darwin", "freebsd")):
        return
    try:
        tv = struct.pack("ll", int(timeout), int((timeout % 1) * 1e6))
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, tv)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDTIMEO, tv)
    except (OSError, struct.error):
        return
    sock.settimeout(None)
