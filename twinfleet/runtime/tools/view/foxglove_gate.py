"""The door of `twinfleet foxglove`: a WebSocket relay that checks who connects.

The Foxglove SDK's server answers any WebSocket that reaches its port, and offers no hook
to look at a connection's ``Host``, ``Origin`` or URL. So the SDK server listens on a free
port of 127.0.0.1 behind this gate, over TLS with a throw-away certificate
(`runtime.host.certs.self_signed`) that only the gate trusts: a web page that finds that
port cannot complete the handshake (a browser never lets a script accept an unknown
certificate). The gate listens on the port the user connects to, applies
`runtime.tools.view.web_guard` (Host, Origin, the per-run token of the printed URL), and
relays the frames of each admitted client to a connection of its own to the SDK server,
unchanged in both directions. The subprotocols the client offers are offered to the SDK
server as they are, and the one it picks is the one the client gets (the SDK speaks
``foxglove.sdk.v1`` and may refuse a client offering only older ones).
"""

from __future__ import annotations

import asyncio
import contextlib
import ssl
from collections.abc import Callable
from typing import final

import aiohttp
from aiohttp import WSMsgType, web

from twinfleet.runtime.host.certs import Pem, self_signed
from twinfleet.runtime.tools.view.web_guard import WebAccess, guard_middleware


def inner_certificate() -> tuple[Pem, ssl.SSLContext]:
    """The SDK server's certificate and the client context that trusts it alone."""
    server, authority = self_signed(["127.0.0.1"])
    return server, ssl.create_default_context(cadata=authority.decode())


@final
class FoxgloveGate:
    """The relay in front of the SDK server on 127.0.0.1:`inner_port` (module docstring)."""

    def __init__(self, inner_port: int, client_tls: ssl.SSLContext, access: WebAccess,
                 log: Callable[[str], None]) -> None:
        self.inner = f"wss://127.0.0.1:{inner_port}/"
        self.client_tls, self.access, self.log = client_tls, access, log
        self.runner: web.AppRunner | None = None
        self.port = 0
        self._http: aiohttp.ClientSession | None = None

    async def start(self, port: int) -> int:
        """Listen on 127.0.0.1:`port` (0: a free one); return the port."""
        app = web.Application(middlewares=[guard_middleware(self.access, self.log)])
        app.router.add_get("/{tail:.*}", self._relay)
        self._http = aiohttp.ClientSession()
        self.runner = web.AppRunner(app, access_log=None, handle_signals=False)
        await self.runner.setup()
        try:
            await web.TCPSite(self.runner, "127.0.0.1", port).start()
        except OSError:
            await self.stop()
            raise
        self.port = int(self.runner.addresses[0][1])
        return self.port

    async def stop(self) -> None:
        """Close every relayed connection and the listener."""
        if self.runner is not None:
            await self.runner.cleanup()
        if self._http is not None:
            await self._http.close()

    async def _relay(self, request: web.Request) -> web.StreamResponse:
        offered = tuple(p.strip() for p in
                        request.headers.get("Sec-WebSocket-Protocol", "").split(",") if p.strip())
        if not web.WebSocketResponse(protocols=offered).can_prepare(request).ok:
            return web.Response(text="a Foxglove WebSocket server: in Foxglove, open "
                                     "connection with this URL (ws://...)\n")
        assert self._http is not None
        try:
            inner = await self._http.ws_connect(self.inner, protocols=offered,
                                                ssl=self.client_tls, max_msg_size=0)
        except aiohttp.WSServerHandshakeError as exc:  # e.g. only a subprotocol it does not speak
            self.log(f"the Foxglove server behind the gate refused a client's handshake: {exc}")
            return web.Response(status=exc.status, text="the Foxglove server refused the "
                                f"handshake (subprotocols offered: {', '.join(offered)})\n")
        except (aiohttp.ClientError, OSError) as exc:
            self.log(f"the Foxglove server behind the gate refused a client: {exc}")
            return web.Response(status=502, text="the Foxglove server refused the connection\n")
        ws = web.WebSocketResponse(protocols=(inner.protocol,) if inner.protocol else (),
                                   max_msg_size=0)
        try:
            await ws.prepare(request)
            pumps = [asyncio.ensure_future(_pump(ws, inner)),
                     asyncio.ensure_future(_pump(inner, ws))]
            _, pending = await asyncio.wait(pumps, return_when=asyncio.FIRST_COMPLETED)
            for task in pending:
                task.cancel()
            await asyncio.gather(*pending, return_exceptions=True)
        finally:
            await inner.close()
            await ws.close()
        return ws


async def _pump(source: web.WebSocketResponse | aiohttp.ClientWebSocketResponse,
                sink: web.WebSocketResponse | aiohttp.ClientWebSocketResponse) -> None:
    """Copy text and binary frames from `source` to `sink` until either closes."""
    async for msg in source:
        with contextlib.suppress(ConnectionError, RuntimeError):
            if msg.type == WSMsgType.TEXT:
                await sink.send_str(msg.data)
            elif msg.type == WSMsgType.BINARY:
                await sink.send_bytes(msg.data)
            else:
                break
