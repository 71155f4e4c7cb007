"""Browser-facing servers answer only the user's own browser: `twinfleet view` and
`twinfleet foxglove` refuse a cross-origin WebSocket, a foreign Host header (DNS rebinding)
and a request without the printed URL's token, with one logged line and no data."""

from __future__ import annotations

import asyncio
import contextlib
import io
from collections.abc import AsyncIterator, Awaitable, Callable

import aiohttp
import pytest
from viewer_support import api

from twinfleet.runtime.tools.view.foxglove_bridge import serve_foxglove
from twinfleet.runtime.tools.view.viewer import serve
from twinfleet.runtime.tools.view.web_guard import FOXGLOVE_APP_ORIGIN, WebAccess, host_name

pytestmark = pytest.mark.timeout(60)

NOWHERE = "tcp/127.0.0.1:9"  # no router: the servers wait for one, and serve meanwhile
PROTOCOLS = ("foxglove.sdk.v1", "foxglove.websocket.v1")


def test_the_decision():
    access = WebAccess(token="s3cret")
    assert access.refusal(8000, "127.0.0.1:8000", None, "s3cret") is None
    assert access.refusal(8000, "localhost:8000", "http://localhost:8000", "s3cret") is None
    assert access.refusal(8000, "[::1]:8000", "http://[::1]:8000", "s3cret") is None
    assert "Host evil.example:8000 is not a name" in access.refusal(
        8000, "evil.example:8000", None, "s3cret")
    assert "Host (none)" in access.refusal(8000, None, None, "s3cret")
    assert "Origin http://evil.example may not" in access.refusal(
        8000, "127.0.0.1:8000", "http://evil.example", "s3cret")
    assert "Origin http://127.0.0.1:9999" in access.refusal(  # another local server's page
        8000, "127.0.0.1:8000", "http://127.0.0.1:9999", "s3cret")
    assert "missing or wrong token" in access.refusal(8000, "127.0.0.1:8000", None, None)
    assert "missing or wrong token" in access.refusal(8000, "127.0.0.1:8000", None, "guess")
    allowed = WebAccess.allowing(["Robots.Lan"], [FOXGLOVE_APP_ORIGIN])
    assert allowed.refusal(1, "robots.lan:1", FOXGLOVE_APP_ORIGIN, allowed.token) is None
    assert WebAccess().token != WebAccess().token  # per run
    assert host_name("[::1]:80") == "::1" and host_name("LOCALHOST") == "localhost"


@contextlib.asynccontextmanager
async def _running(start: Callable[[Callable[[str], None], asyncio.Event], Awaitable[None]]
                   ) -> AsyncIterator[str]:
    """Run a server coroutine; yield the URL it printed (with its token)."""
    stop, printed = asyncio.Event(), asyncio.get_running_loop().create_future()
    task = asyncio.create_task(start(printed.set_result, stop))
    try:
        yield await asyncio.wait_for(printed, 20)
    finally:
        stop.set()
        await asyncio.wait_for(task, 20)


async def _status(url: str, headers: dict[str, str] | None = None,
                  protocols: tuple[str, ...] = ()) -> tuple[int, str]:
    """(HTTP status, first text) of a WebSocket handshake to `url`."""
    async with aiohttp.ClientSession() as http:
        try:
            async with http.ws_connect(url, headers=headers, protocols=protocols) as ws:
                msg = await ws.receive(timeout=10)
                return 101, str(msg.data)
        except aiohttp.WSServerHandshakeError as exc:
            return exc.status, exc.message


async def _get(url: str, headers: dict[str, str] | None = None) -> tuple[int, str]:
    async with aiohttp.ClientSession() as http, http.get(url, headers=headers) as reply:
        return reply.status, await reply.text()


def test_view_refuses_other_origins_hosts_and_a_missing_token():
    out = io.StringIO()

    async def run() -> None:
        def start(ready, stop):
            return serve(connect=NOWHERE, fleet="x", port=0, out=out, ready=ready, stop=stop)

        async with _running(start) as url:
            assert "?token=" in url
            port = url.split(":")[2].split("/")[0]
            ws = api(url, "ws").replace("http://", "ws://")
            # the user's own page: served
            assert (await _get(api(url, "api/state")))[0] == 200
            status, first = await _status(ws, {"Origin": f"http://127.0.0.1:{port}"})
            assert status == 101 and '"kind": "snapshot"' in first
            # another site's page, with the token even: refused, no snapshot
            assert (await _status(ws, {"Origin": "http://evil.example"}))[0] == 403
            # DNS rebinding: the browser sends the attacker's name as Host
            status, text = await _get(api(url, "api/info"), {"Host": f"evil.example:{port}"})
            assert status == 403 and "fleet" not in text and "is not a name" in text
            # no token: nothing, not even the page
            bare = url.split("?")[0]
            for path in ("", "api/info", "api/state", "static/viewer.js"):
                status, text = await _get(bare + path)
                assert status == 403 and "token" in text, path
            assert (await _status(bare.replace("http://", "ws://") + "ws"))[0] == 403
            # the printed URL sets the cookie the page's own requests then carry
            jar = aiohttp.CookieJar(unsafe=True)  # a browser keeps cookies of 127.0.0.1
            async with aiohttp.ClientSession(cookie_jar=jar) as http:
                async with http.get(url) as page:
                    assert page.status == 200
                async with http.get(bare + "api/info") as info:
                    assert info.status == 200

    asyncio.run(run())
    log = out.getvalue()
    assert "[viewer] refused GET /ws from 127.0.0.1: Origin http://evil.example" in log
    assert "[viewer] refused GET /api/info from 127.0.0.1: Host evil.example" in log
    assert "missing or wrong token" in log


@contextlib.asynccontextmanager
async def _foxglove(out: io.StringIO, web: WebAccess) -> AsyncIterator[str]:
    """`serve_foxglove` on a free port; yield the URL it printed."""
    stop = asyncio.Event()
    ports: asyncio.Future[int] = asyncio.get_running_loop().create_future()
    task = asyncio.create_task(serve_foxglove(NOWHERE, "x", port=0, out=out, stop=stop,
                                              ready=ports.set_result, web=web))
    try:
        url = web.url("ws", await asyncio.wait_for(ports, 20))
        assert f"open connection {url}" in out.getvalue()
        yield url
    finally:
        stop.set()
        await asyncio.wait_for(task, 20)


def test_foxglove_refuses_other_origins_hosts_and_a_missing_token():
    out = io.StringIO()

    async def run() -> None:
        async with _foxglove(out, WebAccess()) as url:
            status, first = await _status(url, protocols=PROTOCOLS)
            assert status == 101 and '"op":"serverInfo"' in first
            assert (await _status(url, {"Origin": "http://evil.example"}, PROTOCOLS))[0] == 403
            assert (await _status(url, {"Origin": FOXGLOVE_APP_ORIGIN}, PROTOCOLS))[0] == 403
            port = url.split(":")[2].split("/")[0]
            assert (await _status(url, {"Host": f"evil.example:{port}"}, PROTOCOLS))[0] == 403
            assert (await _status(url.split("?")[0], protocols=PROTOCOLS))[0] == 403

    asyncio.run(run())
    log = out.getvalue()
    assert "refused GET / from 127.0.0.1: Origin http://evil.example" in log
    assert "refused GET / from 127.0.0.1: Host evil.example" in log
    assert "missing or wrong token" in log


def test_foxglove_admits_its_web_app_when_asked():
    async def run() -> None:
        async with _foxglove(io.StringIO(), WebAccess.allowing(origins=[FOXGLOVE_APP_ORIGIN])
                             ) as url:
            status, _ = await _status(url, {"Origin": FOXGLOVE_APP_ORIGIN}, PROTOCOLS)
            assert status == 101

    asyncio.run(run())
