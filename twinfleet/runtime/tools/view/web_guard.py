"""Who a browser-facing server (`twinfleet view`, `twinfleet foxglove`) answers.

A server on 127.0.0.1 is reachable by every web page the user has open: a page of
``evil.example`` may open a WebSocket to ``ws://127.0.0.1:8765`` (browsers do not apply
the same-origin policy to WebSockets), and by DNS rebinding it may even read plain HTTP
answers as its own (its name now resolves to 127.0.0.1, and the request says ``Host:
evil.example``). Three checks, all before anything is served, close those doors:

* **Host.** The ``Host`` header must name this server: 127.0.0.1, localhost, ::1, or a
  name the user allows (``--allow-host``). A rebound name fails here.
* **Origin.** A request that carries an ``Origin`` (every WebSocket a browser opens, and
  cross-site fetches) must come from a page this server serves (``http://HOST:PORT``
  for the hosts above) or an origin the user allows (``--allow-origin``; Foxglove's web
  app with ``--allow-foxglove-app``). Programs that are not browsers send none; the
  token still applies to them.
* **Token.** A per-run secret (`secrets.token_urlsafe`) must come with the request, as
  ``?token=`` (the printed URL carries it, as Jupyter's does) or as the owner-only cookie
  the server sets when it sees a valid one (``SameSite=Strict``, HttpOnly, named after
  the port, since cookies do not tell ports apart), so the page's own requests and
  WebSocket carry it without any script knowing it.

A refusal is an HTTP 403 with one line saying why, written to the server's log too;
no data is sent. `refusal` is the pure decision; `guard_middleware` applies it in aiohttp.
"""

from __future__ import annotations

import hmac
import secrets
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Final

from aiohttp import web

LOCAL_HOSTS: Final = ("127.0.0.1", "localhost", "::1")
FOXGLOVE_APP_ORIGIN: Final = "https://app.foxglove.dev"
TOKEN_PARAM: Final = "token"


@dataclass(frozen=True)
class WebAccess:
    """What a browser-facing server accepts (module docstring).

    Attributes:
        token: the per-run secret of the printed URL.
        hosts: host names besides `LOCAL_HOSTS` (lower case).
        origins: origins besides the server's own (``scheme://host[:port]``).
    """

    token: str = field(default_factory=lambda: secrets.token_urlsafe(24))
    hosts: frozenset[str] = frozenset()
    origins: frozenset[str] = frozenset()

    @classmethod
    def allowing(cls, hosts: Sequence[str] = (), origins: Sequence[str] = ()) -> WebAccess:
        """A fresh token, and the host names and origins the user added."""
        return cls(hosts=frozenset(h.lower().strip("[]") for h in hosts),
                   origins=frozenset(o.rstrip("/").lower() for o in origins))

    def all_hosts(self) -> list[str]:
        """Every host name this server answers to."""
        return [*LOCAL_HOSTS, *sorted(self.hosts - set(LOCAL_HOSTS))]

    def cookie(self, port: int) -> str:
        """The name of the token cookie of the server on `port`."""
        return f"twinfleet-token-{port}"

    def url(self, scheme: str, port: int, path: str = "/") -> str:
        """The URL to print: 127.0.0.1, `port`, `path` and the token."""
        return f"{scheme}://127.0.0.1:{port}{path}?{TOKEN_PARAM}={self.token}"

    def refusal(self, port: int, host: str | None, origin: str | None,
                token: str | None) -> str | None:
        """Why a request with these headers (and this token) is refused, or None."""
        name = host_name(host)
        if name is None or name not in self.all_hosts():
            return (f"Host {host or '(none)'} is not a name of this server (it answers to "
                    f"{', '.join(self.all_hosts())}; --allow-host NAME adds one)")
        if origin is not None and origin.rstrip("/").lower() not in self._origins(port):
            return (f"Origin {origin} may not use this server (a page it did not serve; "
                    "--allow-origin ORIGIN allows one)")
        if token is None or not hmac.compare_digest(token.encode(), self.token.encode()):
            return ("missing or wrong token: open the URL the server printed (it ends with "
                    f"?{TOKEN_PARAM}=...)")
        return None

    def _origins(self, port: int) -> set[str]:
        own = {f"{scheme}://{_bracketed(h)}:{port}" for h in self.all_hosts()
               for scheme in ("http", "https")}
        return own | set(self.origins)


def host_name(header: str | None) -> str | None:
    """The host name of a ``Host`` header, lower case, without port or brackets."""
    if not header:
        return None
    header = header.strip().lower()
    if header.startswith("["):
        end = header.find("]")
        return header[1:end] if end > 0 else None
    return header.rsplit(":", 1)[0] if header.count(":") == 1 else header


def _bracketed(host: str) -> str:
    return f"[{host}]" if ":" in host else host


def guard_middleware(access: WebAccess, log: Callable[[str], None]) -> Any:
    """An aiohttp middleware that refuses what `access` refuses (403, one line, logged) and
    sets the token cookie when a request brings the token in its URL."""

    @web.middleware
    async def guard(request: web.Request, handler: Any) -> web.StreamResponse:
        port = _server_port(request)
        cookie = access.cookie(port)
        given = request.query.get(TOKEN_PARAM) or request.cookies.get(cookie)
        why = access.refusal(port, request.headers.get("Host"),
                             request.headers.get("Origin"), given)
        if why is not None:
            log(f"refused {request.method} {request.path} from {request.remote}: {why}")
            return web.Response(status=403, text=why + "\n")
        response = await handler(request)
        if request.query.get(TOKEN_PARAM) and not isinstance(response, web.WebSocketResponse) \
                and not response.prepared:
            response.set_cookie(cookie, access.token, httponly=True, samesite="Strict",
                                path="/")
        return response

    return guard


def _server_port(request: web.Request) -> int:
    sockname = request.transport.get_extra_info("sockname") if request.transport else None
    return int(sockname[1]) if sockname else 0
