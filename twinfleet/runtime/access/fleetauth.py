"""A launch's credentials: who may join its router, who may publish, and the fleet key.

Each `twinfleet launch` that embeds its router draws fresh secrets
(`FleetCredentials.fresh`) and starts the router with Zenoh's own
user/password authentication (``transport/auth/usrpwd``, a dictionary file in
an owner-only temporary directory) and access control (``access_control``):

* user ``node`` — the fleet's node processes (and the owner's operator
  commands: ``topic pub``, ``service call``) may do everything;
* user ``monitor`` — read-only: subscribe, query, read liveliness; its puts,
  replies and tokens are denied by the router;
* anyone else cannot open a session on the router at all.

On top of that, the fleet key (`runtime.core.guard`) signs every sample, so what a
node, the run report or the shutdown topic accepts comes from a holder of the
key even on a router the launcher does not control (``--connect``).

A fleet launched with a bridge to another system (``launch --ros2``) also draws a
*bridge key* (`guard.BRIDGE_KEY_ENV`): its nodes accept a sample signed with it on
their ``external_topics`` only, and count it; the bridge signs with it and never with
the fleet key.

A fleet that listens on ``tls/`` or ``quic/`` also has its own certificate authority
(`runtime.host.certs`): the router presents a server certificate it signed, and every
client trusts that authority's certificate alone (`FleetCredentials.tls_ca`,
`tls_settings`), so a client reaches this launch's router or nothing.

Nodes get their secrets from the launcher in the environment (`ENV_USER`,
`ENV_PASSWORD`, `ENV_TLS_CA`, `guard.KEY_ENV`). Monitors get them from the fleet registry
(owner-only, `runtime.access.registry`; `registry_extra`), or from ``--credentials
FILE`` — a registry entry file copied to where the monitor runs.
"""

from __future__ import annotations

import base64
import ipaddress
import json
import os
import secrets
import shutil
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from twinfleet.runtime.contract.environment import EnvVar, env_value
from twinfleet.runtime.core.guard import BRIDGE_KEY_ENV, KEY_ENV, key_from_env, new_key

ENV_USER: Final = EnvVar.ZENOH_USER
ENV_PASSWORD: Final = EnvVar.ZENOH_PASSWORD
ENV_TLS_CA: Final = EnvVar.TLS_CA  # the fleet authority's certificate, PEM
SECURE_SCHEMES: Final = ("tls/", "quic/")
#: set (to 1) for the nodes of a fleet launched to accept recorded input (``play --into-fleet``)
ENV_ACCEPT_RECORDED: Final = EnvVar.ACCEPT_RECORDED
NODE_USER: Final = "node"
MONITOR_USER: Final = "monitor"
_WRITES: Final = ["put", "delete", "reply", "declare_queryable", "liveliness_token"]


class CredentialsError(ValueError):
    """Credentials cannot be read; the text says which and why."""


@dataclass(frozen=True)
class Login:
    """A Zenoh user and password (None: an unauthenticated session)."""

    user: str
    password: str

    def settings(self) -> dict[str, Any]:
        """The client config keys of this login."""
        return {"transport/auth/usrpwd/user": self.user,
                "transport/auth/usrpwd/password": self.password}


@dataclass(frozen=True)
class FleetCredentials:
    """The secrets of one launch (module docstring)."""

    key: bytes
    node: Login
    monitor: Login
    bridge: bytes | None = None  # the bridge key, for a fleet that takes external input
    tls_ca: bytes | None = None  # the fleet authority's certificate (PEM) on tls/quic

    @classmethod
    def fresh(cls, *, bridge: bool = False) -> FleetCredentials:
        """New random secrets (and a bridge key, with `bridge`)."""
        return cls(new_key(), Login(NODE_USER, secrets.token_urlsafe(24)),
                   Login(MONITOR_USER, secrets.token_urlsafe(24)),
                   new_key() if bridge else None)

    def node_env(self) -> dict[str, str]:
        """What a node process needs in its environment."""
        env: dict[str, str] = {KEY_ENV: self.key.hex(), ENV_USER: self.node.user,
               ENV_PASSWORD: self.node.password}
        if self.bridge is not None:
            env[BRIDGE_KEY_ENV] = self.bridge.hex()
        if self.tls_ca is not None:
            env[ENV_TLS_CA] = self.tls_ca.decode()
        return env

    def registry_extra(self) -> dict[str, Any]:
        """The ``auth`` entry of the fleet registry (owner-only file)."""
        auth: dict[str, Any] = {"key": self.key.hex(),
                                "operator": [self.node.user, self.node.password],
                                "monitor": [self.monitor.user, self.monitor.password]}
        if self.bridge is not None:
            auth["bridge"] = self.bridge.hex()
        if self.tls_ca is not None:
            auth["tls_ca"] = self.tls_ca.decode()
        return {"auth": auth}


def secure(endpoint: str) -> bool:
    """True for an endpoint whose links are encrypted (``tls/``, ``quic/``)."""
    return endpoint.startswith(SECURE_SCHEMES)


def tls_settings(ca: bytes | None) -> dict[str, Any]:
    """Client config keys that trust the fleet authority `ca` alone (none without one)."""
    if ca is None:
        return {}
    return {"transport/link/tls/root_ca_certificate_base64": base64.b64encode(ca).decode()}


def router_tls_settings(certificate: bytes, key: bytes) -> dict[str, Any]:
    """Router config keys that present `certificate` (PEM; its `key` PKCS#8 PEM) on tls/quic."""
    return {"transport/link/tls/listen_certificate_base64": base64.b64encode(certificate).decode(),
            "transport/link/tls/listen_private_key_base64": base64.b64encode(key).decode()}


def router_settings(creds: FleetCredentials, directory: Path) -> dict[str, Any]:
    """Config keys of an embedded router that admits only `creds`' users, with their rights.

    Writes the user dictionary into `directory` (owner-only; the caller removes it).
    """
    users = directory / "users.txt"
    fd = os.open(users, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as f:
        for login in (creds.node, creds.monitor):
            f.write(f"{login.user}:{login.password}\n")
    # Default allow: the router admits only the two users (usrpwd), and a deny-by-default
    # policy also cuts the router's own session and liveliness off (measured on 1.10.2).
    acl = {"enabled": True, "default_permission": "allow",
           "rules": [{"id": "no_writes", "messages": _WRITES, "flows": ["ingress"],
                      "permission": "deny", "key_exprs": ["**"]}],
           "subjects": [{"id": "monitors", "usernames": [creds.monitor.user]}],
           "policies": [{"id": "monitors_read_only", "rules": ["no_writes"],
                         "subjects": ["monitors"]}]}
    # the router's own login: it is a member of the fleet when it connects anywhere
    return {**creds.node.settings(), "transport/auth/usrpwd/dictionary_file": str(users),
            "access_control": acl}


def private_dir() -> Path:
    """A fresh owner-only directory for a router's user dictionary."""
    return Path(tempfile.mkdtemp(prefix="twinfleet-auth-"))


def remove_dir(path: Path | None) -> None:
    """Remove a `private_dir` (nothing if None or gone)."""
    if path is not None:
        shutil.rmtree(path, ignore_errors=True)


def node_login(env: Mapping[str, str] | None = None) -> Login | None:
    """The login the launcher gave this node process, or None."""
    user, password = env_value(EnvVar.ZENOH_USER, env), env_value(EnvVar.ZENOH_PASSWORD, env)
    return Login(user, password) if user and password else None


def node_secrets(env: Mapping[str, str] | None = None) -> tuple[Login | None, bytes | None]:
    """(login, fleet key) from a node process's environment."""
    return node_login(env), key_from_env(env)


def accepts_recorded(env: Mapping[str, str] | None = None) -> bool:
    """True when this node process's fleet was launched with ``--accept-recorded``."""
    return env_value(EnvVar.ACCEPT_RECORDED, env) == "1"


def node_tls(env: Mapping[str, str] | None = None) -> dict[str, Any]:
    """The client TLS config keys of a node process (the fleet authority in its environment)."""
    ca = env_value(EnvVar.TLS_CA, env)
    return tls_settings(ca.encode()) if ca else {}


@dataclass(frozen=True)
class MonitorAuth:
    """What a monitor command uses: a login for reading, one for operating, the fleet key."""

    key: bytes | None = None
    operator: Login | None = None
    monitor: Login | None = None
    bridge: bytes | None = None  # set when the fleet was launched to take external input
    tls_ca: bytes | None = None  # the fleet authority's certificate (a tls/quic fleet)

    def login(self, *, write: bool) -> Login | None:
        """The login for a command that publishes or calls (`write`) or only reads."""
        return (self.operator if write else self.monitor) or self.operator


def monitor_auth(extra: Mapping[str, Any]) -> MonitorAuth:
    """The `MonitorAuth` of a registry entry's ``extra`` (empty: an open fleet).

    Raises:
        CredentialsError: the ``auth`` entry is malformed.
    """
    auth = extra.get("auth")
    if not auth:
        return MonitorAuth()
    try:
        key = bytes.fromhex(auth["key"]) if auth.get("key") else None
        operator = Login(*auth["operator"]) if auth.get("operator") else None
        monitor = Login(*auth["monitor"]) if auth.get("monitor") else None
        bridge = bytes.fromhex(auth["bridge"]) if auth.get("bridge") else None
        tls_ca = auth["tls_ca"].encode() if auth.get("tls_ca") else None
    except (TypeError, ValueError, KeyError, AttributeError) as exc:
        raise CredentialsError(f"fleet credentials: malformed auth entry ({exc})") from None
    return MonitorAuth(key, operator, monitor, bridge=bridge, tls_ca=tls_ca)


def read_credentials(path: str) -> tuple[str | None, MonitorAuth]:
    """(endpoint, auth) from a registry entry file given with ``--credentials``.

    Raises:
        CredentialsError: unreadable, not JSON, or readable by others.
    """
    try:
        info = os.stat(path)
        doc = json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        raise CredentialsError(f"--credentials {path}: {exc}") from None
    if info.st_mode & 0o077:
        raise CredentialsError(f"--credentials {path}: others may read it (mode "
                               f"{info.st_mode & 0o777:o}); run chmod 600 {path}")
    if not isinstance(doc, dict):
        raise CredentialsError(f"--credentials {path}: expected a fleet registry entry (JSON map)")
    return doc.get("endpoint"), monitor_auth(doc.get("extra") or doc)


def loopback_only(endpoint: str) -> bool:
    """True when a Zenoh endpoint listens on a loopback address only."""
    locator = endpoint.split("#", 1)[0]
    _, _, address = locator.partition("/")
    host = address.rsplit(":", 1)[0].strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False  # a name or an interface: may be reachable from elsewhere


def listen_problem(endpoint: str, *, insecure: bool) -> str | None:
    """Why `--listen endpoint` must not be used as it is, or None.

    A non-loopback endpoint exposes the fleet's credentials exchange and traffic to the
    network: only ``tls/`` or ``quic/`` (certificates in the Zenoh config) are accepted
    there, unless the user says ``--insecure-listen``.
    """
    if insecure or loopback_only(endpoint) or secure(endpoint):
        return None
    return (f"--listen {endpoint} is reachable from other machines, and plain tcp/udp sends "
            "every message in clear text to anyone on the path: use a tls/ (or quic/) "
            "endpoint (the launch makes the certificates; remote hosts join with "
            "--credentials), or pass --insecure-listen to accept that risk")


def registry_auth(endpoint: str) -> MonitorAuth:
    """The secrets of the fleet this machine's registry lists at `endpoint` (none: empty).

    A command given ``--connect`` to a fleet launched here by the same user needs
    no ``--credentials``.
    """
    from twinfleet.runtime.access.registry import RegistryError, running_fleets

    try:
        entries = [e for e in running_fleets() if e.endpoint == endpoint]
        return monitor_auth(entries[-1].extra) if entries else MonitorAuth()
    except (OSError, RegistryError, CredentialsError):
        return MonitorAuth()


def login_settings(auth: MonitorAuth, *, write: bool = False) -> dict[str, Any]:
    """The client config keys of `auth`'s login for reading (or writing) and of its fleet
    authority (a tls/quic fleet), or none."""
    login = auth.login(write=write)
    return {**(login.settings() if login else {}), **tls_settings(auth.tls_ca)}
