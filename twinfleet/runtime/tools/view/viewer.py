"""`twinfleet view`: a local web page that watches a running fleet or steps through a trace.

An aiohttp application served on 127.0.0.1 only:

    GET /                 the page (runtime/static/index.html + viewer.js; no CDN, no build)
    GET /api/info         {"mode": "live"|"trace", "fleet", "connect", ...}
    GET /api/state        the live state as one JSON snapshot (what a new page first gets)
    GET /api/trace        the trace document (trace mode)
    GET /ws               websocket: one "snapshot", then an "update" every 50 ms with changes

Live mode. A `runtime.tools.monitor.tap.FleetTap` opens one Zenoh client session (retrying
until the router is up, so the viewer may start before `twinfleet launch`) and
hears every topic of the fleet. Samples are folded into a `LiveState` on the
loop; a flush task sends the changes to every page every 50 ms. The fleet's
first sample makes a `runtime.tools.view.scene_finder.SceneFinder` ask the
fleet how it is drawn (its scene) and which topics are latched, which the tap
then hears with history, so a viewer that joins late still gets the map.

Without --connect, the viewer takes the fleet from the fleet registry
(`runtime.access.registry`), and if none runs yet it waits for one to be launched.

Only the user's own browser gets an answer: every request passes
`runtime.tools.view.web_guard` (its Host, its Origin, the per-run token of the
printed URL), else it is refused with one line and logged.

Trace mode (``--trace FILE``) serves `trace_document(FILE)`; the page steps
through it. No Zenoh session is opened.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import sys
import time
import weakref
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any, TextIO

from aiohttp import WSMsgType, web

from twinfleet.runtime.tools.view.viewstate import LiveState, trace_document
from twinfleet.runtime.tools.view.web_guard import WebAccess, guard_middleware

STATIC_DIR = Path(__file__).with_name("static")
FLUSH_S = 0.05
LINK_CHECK_S = 1.0

_STATE: web.AppKey[Any] = web.AppKey("state")  # LiveState | None
_TRACE: web.AppKey[Any] = web.AppKey("trace")  # trace document | None
_INFO = web.AppKey("info", dict)
_SOCKETS: web.AppKey[weakref.WeakSet[Any]] = web.AppKey("sockets")
_TAP: web.AppKey[Any] = web.AppKey("tap")  # FleetTap | None
_FINDER: web.AppKey[Any] = web.AppKey("finder")  # SceneFinder | None


def make_app(*, state: LiveState | None = None, trace: dict[str, Any] | None = None,
             info: dict[str, Any] | None = None, tap: Any = None,
             finder: Any = None, access: WebAccess | None = None,
             log: Callable[[str], None] = print) -> web.Application:
    """The aiohttp application: the page, its script, the JSON API and the websocket.

    Args:
        state: live mode: the state the pages show; a flush task pushes its changes.
        trace: trace mode: the document from `trace_document`.
        info: extra fields of /api/info.
        tap: live mode: the `FleetTap` feeding `state`; opened and closed with the app.
        finder: live mode: the `SceneFinder` using `tap`; its question ends before the tap.
        access: who may read (`web_guard`); None: anyone who reaches the port (tests only).
        log: where refusals are written.
    """
    app = web.Application(middlewares=[guard_middleware(access, log)] if access else [])
    app[_STATE], app[_TRACE], app[_TAP], app[_FINDER] = state, trace, tap, finder
    app[_INFO] = {"mode": "trace" if trace is not None else "live", **(info or {})}
    app[_SOCKETS] = weakref.WeakSet()
    app.router.add_get("/", _index)
    app.router.add_get("/api/info", _info)
    app.router.add_get("/api/state", _state)
    app.router.add_get("/api/trace", _trace)
    app.router.add_get("/ws", _websocket)
    app.router.add_static("/static/", STATIC_DIR, append_version=False)
    app.on_shutdown.append(_close_sockets)
    if state is not None:
        app.cleanup_ctx.append(_live)
    return app


async def _live(app: web.Application) -> AsyncIterator[None]:
    """Open the tap and run the flush task for the app's lifetime; close both after."""
    tap = app[_TAP]
    tasks = [asyncio.create_task(_flush(app))]
    if tap is not None:
        tasks.append(asyncio.create_task(tap.open()))
    yield
    if tap is not None:
        tap.stop()
    tasks[0].cancel()
    await asyncio.gather(*tasks, return_exceptions=True)  # open() ends after one attempt
    if app[_FINDER] is not None:
        await app[_FINDER].close()
    if tap is not None:
        await tap.close()


async def _close_sockets(app: web.Application) -> None:
    sockets = app[_SOCKETS]
    for ws in list(sockets):
        with contextlib.suppress(Exception):
            await ws.close()


async def _index(_request: web.Request) -> web.FileResponse:
    return web.FileResponse(STATIC_DIR / "index.html", headers={"Cache-Control": "no-store"})


async def _info(request: web.Request) -> web.Response:
    return web.json_response(request.app[_INFO])


async def _state(request: web.Request) -> web.Response:
    state = request.app[_STATE]
    if state is None:
        raise web.HTTPNotFound(text="no live fleet in trace mode")
    return web.json_response(state.snapshot())


async def _trace(request: web.Request) -> web.Response:
    doc = request.app[_TRACE]
    if doc is None:
        raise web.HTTPNotFound(text="no trace: start the viewer with --trace FILE")
    return web.json_response(doc)


async def _websocket(request: web.Request) -> web.WebSocketResponse:
    ws = web.WebSocketResponse(heartbeat=20.0)
    await ws.prepare(request)
    state = request.app[_STATE]
    if state is not None:
        await ws.send_str(json.dumps(state.snapshot()))
    request.app[_SOCKETS].add(ws)
    async for msg in ws:  # the page sends nothing we need; read until it closes
        if msg.type == WSMsgType.ERROR:
            break
    return ws


async def _flush(app: web.Application) -> None:
    """Every FLUSH_S: send the state's changes to every open page. Every LINK_CHECK_S:
    record the link, and without a router, let the tap follow a fleet launched again."""
    state, tap = app[_STATE], app[_TAP]
    next_link = 0.0
    reopening: asyncio.Task[bool] | None = None
    try:
        while True:
            await asyncio.sleep(FLUSH_S)
            if tap is not None and time.monotonic() >= next_link:
                next_link = time.monotonic() + LINK_CHECK_S
                router = tap.routers() > 0
                state.set_link(tap.is_open, router)
                if not router and (reopening is None or reopening.done()):
                    reopening = asyncio.create_task(tap.reopen_if_stale())
            update = state.take_update()
            if update is None:
                continue
            text = json.dumps(update)
            sockets = app[_SOCKETS]
            for ws in list(sockets):
                if not ws.closed:
                    with contextlib.suppress(ConnectionError, RuntimeError):
                        await ws.send_str(text)
    finally:  # the tap was stopped first (`_live`): a reopen ends after its attempt
        if reopening is not None:
            await asyncio.gather(reopening, return_exceptions=True)


async def serve(*, connect: str | None, fleet: str = "*", port: int = 0,
                trace_path: str | None = None, out: TextIO = sys.stdout,
                ready: Callable[[str], None] | None = None,
                stop: asyncio.Event | None = None, auth: Any = None,
                web_access: WebAccess | None = None) -> None:
    """Serve the viewer on 127.0.0.1:`port` until `stop` is set (or the task is cancelled).

    Args:
        connect: Zenoh router endpoint of the fleet (live mode).
        fleet: fleet name, ``*`` for the first one seen.
        port: TCP port; 0 picks a free one (the URL is printed).
        trace_path: serve this checker trace instead of a live fleet.
        out: where the URL line goes.
        ready: called with the page's URL (with its token) once the server listens.
        stop: set it to end the server.
        auth: the fleet's credentials (`runtime.access.fleetauth.MonitorAuth`, from
            ``--credentials``; default: this machine's registry).
        web_access: who may read the page (default: a fresh token, the local host names).
    """
    access = web_access or WebAccess()

    def log(text: str) -> None:
        print(f"[viewer] {text}", file=out, flush=True)

    if trace_path is not None:
        app = make_app(trace=trace_document(trace_path), info={"trace": trace_path},
                       access=access, log=log)
    else:
        from twinfleet.runtime.tools.monitor.tap import FleetTap, tap_config
        from twinfleet.runtime.tools.view.scene_finder import SceneFinder

        state = LiveState(fleet, scene_known=False)

        def deliver(key: str, payload: bytes) -> None:
            finder.seen(key)
            state.on_sample(key, payload)

        make_config = (lambda: tap_config(connect, auth)) if connect else _registry_config(fleet)
        tap = FleetTap(make_config, fleet, deliver)
        finder = SceneFinder(tap, state.set_scene, out=out)
        # The page's header says where the fleet is found; whether it is reached yet is the
        # link indicator's to say (it follows the tap), not a word frozen at start-up.
        app = make_app(state=state, tap=tap, finder=finder, access=access, log=log, info={
            "fleet": fleet, "connect": connect or "the fleet registry"})
    runner = web.AppRunner(app, access_log=None, handle_signals=False)
    await runner.setup()
    try:
        site = web.TCPSite(runner, "127.0.0.1", port)
        await site.start()
        url = access.url("http", runner.addresses[0][1])
        what = (f"trace {trace_path}" if trace_path else
                f"fleet {fleet!r} via {connect or 'the fleet registry (waiting for a launch)'}")
        print(f"[viewer] {what}: open {url}", file=out, flush=True)
        if ready is not None:
            ready(url)
        await (stop.wait() if stop is not None else asyncio.Event().wait())
    finally:
        await runner.cleanup()


def _registry_config(fleet: str) -> Callable[[], Any]:
    """A tap config for the fleet the registry names; `LookupError` (retried) until one runs."""
    from twinfleet.runtime.access.registry import RegistryError, find_fleet
    from twinfleet.runtime.tools.monitor.tap import tap_config

    def make() -> Any:
        try:
            return tap_config(find_fleet(fleet).endpoint)
        except RegistryError as exc:
            raise LookupError(str(exc)) from None
    return make


def run_viewer(*, connect: str | None, fleet: str = "*", port: int = 0,
               trace_path: str | None = None, out: TextIO = sys.stdout, auth: Any = None,
               web: WebAccess | None = None) -> int:
    """Blocking entry point of `twinfleet view`: serve until SIGINT/SIGTERM; exit code."""
    import signal

    async def main() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        await serve(connect=connect, fleet=fleet, port=port, trace_path=trace_path, out=out,
                    stop=stop, auth=auth, web_access=web)

    asyncio.run(main())
    return 0
