"""The subprotocol `twinfleet foxglove` speaks is the one its help and the README name.

A protocol client (aiohttp, no foxglove code) opens the bridge's server with each
name a Foxglove client may offer: ``foxglove.sdk.v1`` gets the server's
``serverInfo``; the older ``foxglove.websocket.v1`` alone is refused at the
handshake (foxglove-sdk has no setting to accept it), as the help says; a
client offering both gets ``foxglove.sdk.v1``.
"""

from __future__ import annotations

import asyncio
import json
import re

import aiohttp
import pytest
from viewer_support import ROOT, free_port, poll

from twinfleet.cli import build_parser

pytestmark = pytest.mark.timeout(60)

CURRENT, OLDER = "foxglove.sdk.v1", "foxglove.websocket.v1"


async def _handshake(url: str, offered: list[str]) -> tuple[str | None, dict | int]:
    """(the subprotocol chosen, the first message) or (None, the HTTP status of a refusal)."""
    try:
        async with aiohttp.ClientSession() as http, http.ws_connect(url, protocols=offered) as ws:
            first = await ws.receive(timeout=5)
            return ws.protocol, json.loads(first.data)
    except aiohttp.WSServerHandshakeError as exc:
        return None, exc.status


def test_each_subprotocol_name_against_the_bridge_and_its_help(cli):
    port = free_port()
    bridge = cli("foxglove", "--connect", f"tcp/127.0.0.1:{free_port()}", "--fleet", "nobody",
                 "--port", str(port), log="foxglove.log")
    poll(lambda: "open connection ws://" in bridge.log.read_text(), 20, "the Foxglove server")
    # the printed URL: the server answers only requests that carry its per-run token
    url = re.search(r"ws://\S+", bridge.log.read_text()).group()

    chosen, first = asyncio.run(_handshake(url, [CURRENT]))
    assert chosen == CURRENT and isinstance(first, dict) and first["op"] == "serverInfo"
    assert asyncio.run(_handshake(url, [OLDER])) == (None, 400)
    chosen, first = asyncio.run(_handshake(url, [OLDER, CURRENT]))
    assert chosen == CURRENT and isinstance(first, dict) and first["op"] == "serverInfo"

    parser = build_parser()
    sub = next(a for a in parser._actions if hasattr(a, "choices") and a.choices
               and "foxglove" in a.choices).choices["foxglove"]
    help_text = " ".join(sub.format_help().split())
    assert f"subprotocol {CURRENT}" in help_text
    assert f"only the older name {OLDER}" in help_text and "refused" in help_text
    readme = " ".join((ROOT / "README.md").read_text().split())
    assert f"subprotocol name `{CURRENT}` only" in readme and f"`{OLDER}`" in readme
