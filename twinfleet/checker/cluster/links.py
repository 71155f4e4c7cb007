"""Direct TCP links between the workers of a relaxed-order search.

A relaxed-order search (`checker.cluster.flow`) waits for nothing but the answers
to its claims, so their round trip sets its pace where the frontier is narrow.
Through Ray's actor calls that round trip took 3.7-3.8 ms (median, two workers busy
on this 2-core machine); over a plain TCP connection between the two processes it
is 0.3 ms with both busy. So Ray starts the workers and carries everything else,
and the claims and answers go over these links.

Each worker listens on its node's address (127.0.0.1 in a local cluster) and opens
two connections to every other worker: one for its claims (written by its loop)
and one for its answers to that worker's claims (written by the thread reading
that worker's claims). A thread reads each incoming connection and never blocks on
anything but it and the answers connection it writes to, whose reader only
appends: so no two writers wait on each other. A connection is accepted only after
it sent the search's token (random, from the coordinator through Ray, whose own
connections are authenticated), then its sender's index and kind.

A frame is a batch number (u64), a length (u32) and that many bytes.
"""

from __future__ import annotations

import contextlib
import hmac
import socket
import struct
import threading
from collections.abc import Callable
from enum import IntEnum
from typing import final

TOKEN_BYTES = 32
_HELLO = struct.Struct("<IB")  # sender index, link kind
_FRAME = struct.Struct("<QI")  # batch number, payload length


class Kind(IntEnum):
    """What a connection carries."""

    CLAIMS = 1
    ANSWERS = 2


def _read(conn: socket.socket, n: int) -> bytes | None:
    """Exactly `n` bytes, or None at the end of the connection."""
    parts, left = [], n
    while left:
        chunk = conn.recv(min(left, 1 << 20))
        if not chunk:
            return None
        parts.append(chunk)
        left -= len(chunk)
    return b"".join(parts)


def _send(conn: socket.socket, batch: int, payload: bytes) -> None:
    conn.sendall(_FRAME.pack(batch, len(payload)) + payload)


@final
class Links:
    """One worker's links (module docstring).

    Args:
        index: this worker's index.
        host: the address to listen on.
        token: the search's token (`TOKEN_BYTES` random bytes).
        on_claims: called with (sender, batch, claims) on a reading thread; returns the
            answer to send back.
        on_answer: called with (batch, answer) on a reading thread.
    """

    def __init__(self, index: int, host: str, token: bytes,
                 on_claims: Callable[[int, int, bytes], bytes],
                 on_answer: Callable[[int, bytes], None]) -> None:
        self.index, self.token = index, token
        self.on_claims, self.on_answer = on_claims, on_answer
        self._server = socket.create_server((host, 0))
        self.address = (host, self._server.getsockname()[1])
        self._claims: dict[int, socket.socket] = {}  # peer -> our claims to it
        self._answers: dict[int, socket.socket] = {}  # peer -> our answers to it
        self._incoming: list[socket.socket] = []
        self._closing = False
        self.error: str | None = None  # the first failure of a link, for the loop to raise
        threading.Thread(target=self._accept, name="links-accept", daemon=True).start()

    def connect(self, addresses: list[tuple[str, int]]) -> None:
        """Open the claims and answers connections to every other worker."""
        for peer, address in enumerate(addresses):
            if peer == self.index:
                continue
            for kind, table in ((Kind.CLAIMS, self._claims), (Kind.ANSWERS, self._answers)):
                conn = socket.create_connection(address, timeout=30)
                conn.settimeout(None)
                conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                conn.sendall(self.token + _HELLO.pack(self.index, kind))
                table[peer] = conn

    def claim(self, peer: int, batch: int, blob: bytes) -> None:
        """Send a batch of claims to `peer` (from the worker's loop only)."""
        _send(self._claims[peer], batch, blob)

    def close(self) -> None:
        """Close every connection (the reading threads end)."""
        self._closing = True
        for conn in (self._server, *self._claims.values(), *self._answers.values(),
                     *self._incoming):
            with contextlib.suppress(OSError):  # already closed by the other end
                conn.shutdown(socket.SHUT_RDWR)  # wakes a thread reading it
            conn.close()

    def _accept(self) -> None:
        while not self._closing:
            try:
                conn, _ = self._server.accept()
            except OSError:
                return
            threading.Thread(target=self._serve, args=(conn,), name="links-read",
                             daemon=True).start()

    def _serve(self, conn: socket.socket) -> None:
        try:
            hello = _read(conn, TOKEN_BYTES + _HELLO.size)
            if hello is None or not hmac.compare_digest(hello[:TOKEN_BYTES], self.token):
                conn.close()  # not one of this search's workers
                return
            peer, kind = _HELLO.unpack(hello[TOKEN_BYTES:])
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._incoming.append(conn)
            while (head := _read(conn, _FRAME.size)) is not None:
                batch, size = _FRAME.unpack(head)
                payload = _read(conn, size)
                if payload is None:
                    break
                if kind == Kind.CLAIMS:
                    _send(self._answers[peer], batch, self.on_claims(peer, batch, payload))
                else:
                    self.on_answer(batch, payload)
            if not self._closing:
                self.error = (f"worker {peer} closed its link before the search ended, "
                              "no verdict")
        except (OSError, KeyError, struct.error) as exc:
            if not self._closing and self.error is None:
                self.error = f"a link between the workers failed, no verdict: {exc}"
