"""Certificates a launch makes for itself: a per-fleet authority and the server certificates
it signs (the `cryptography` package; no files, no network).

A fleet that listens on ``tls/`` or ``quic/`` needs a certificate its clients can check. No
public authority signs ``127.0.0.1`` or a laptop's name, and asking the user to run one is
the hand work this module removes: each launch draws a fresh *fleet authority* (an ECDSA
P-256 key and a self-signed CA certificate, valid for `VALIDITY`), signs with it one
server certificate naming the host's addresses and names, and hands the authority's
certificate, never its key, to whoever joins (the credentials file). A client that trusts
only that certificate reaches only this launch's router: another fleet's router, or a
man in the middle with a certificate of its own, fails the TLS handshake.

The same helpers make the throw-away certificate of a local server behind a proxy
(`self_signed`), which no browser trusts.
"""

from __future__ import annotations

import contextlib
import datetime
import ipaddress
import secrets
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Final

VALIDITY: Final = datetime.timedelta(days=30)
_SKEW: Final = datetime.timedelta(minutes=5)  # clocks of two hosts differ a little


@dataclass(frozen=True)
class Pem:
    """A certificate and its private key, PEM-encoded (the key as PKCS#8)."""

    certificate: bytes
    key: bytes


def _new_key() -> Any:
    from cryptography.hazmat.primitives.asymmetric import ec

    return ec.generate_private_key(ec.SECP256R1())


def _key_pem(key: Any) -> bytes:
    from cryptography.hazmat.primitives import serialization

    return key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                             serialization.NoEncryption())


def _builder(subject: str, issuer: str, public_key: Any) -> Any:
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    now = datetime.datetime.now(datetime.UTC)
    return (x509.CertificateBuilder()
            .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, subject)]))
            .issuer_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, issuer)]))
            .public_key(public_key).serial_number(int.from_bytes(secrets.token_bytes(16)) >> 1)
            .not_valid_before(now - _SKEW).not_valid_after(now + VALIDITY))


def fleet_authority(fleet: str) -> Pem:
    """A fresh CA certificate and key for the fleet named `fleet`."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization

    key = _new_key()
    name = f"twinfleet fleet {fleet} authority"
    cert = (_builder(name, name, key.public_key())
            .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
            .add_extension(x509.KeyUsage(False, False, False, False, False, True, True, False,
                                         False), critical=True)
            .sign(key, hashes.SHA256()))
    return Pem(cert.public_bytes(serialization.Encoding.PEM), _key_pem(key))


def server_certificate(authority: Pem, names: Sequence[str]) -> Pem:
    """A server certificate signed by `authority` for host `names` (addresses or DNS names;
    the first is its common name)."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization

    ca_cert = x509.load_pem_x509_certificate(authority.certificate)
    ca_key = serialization.load_pem_private_key(authority.key, None)
    key = _new_key()
    issuer = ca_cert.subject.rfc4514_string().removeprefix("CN=")
    cert = (_builder(names[0], issuer, key.public_key())
            .add_extension(x509.SubjectAlternativeName([_general_name(n) for n in names]),
                           critical=False)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(x509.ExtendedKeyUsage([x509.ExtendedKeyUsageOID.SERVER_AUTH]),
                           critical=False)
            .sign(ca_key, hashes.SHA256()))
    return Pem(cert.public_bytes(serialization.Encoding.PEM), _key_pem(key))


def self_signed(names: Sequence[str]) -> tuple[Pem, bytes]:
    """A server certificate for `names` and the certificate of the throw-away authority that
    signed it (what a client trusts)."""
    authority = fleet_authority("local")
    return server_certificate(authority, names), authority.certificate


def _general_name(name: str) -> Any:
    from cryptography import x509

    try:
        return x509.IPAddress(ipaddress.ip_address(name.strip("[]")))
    except ValueError:
        return x509.DNSName(name)


def host_names(host: str) -> list[str]:
    """The names a server certificate for a router listening on `host` must carry: the
    address itself unless it is a wildcard, this machine's name and addresses, and the
    loopback names (a client on the same machine)."""
    import socket

    names: list[str] = []
    if host not in ("0.0.0.0", "::", "[::]", ""):
        names.append(host.strip("[]"))
    hostname = socket.gethostname()
    names.append(hostname)
    with contextlib.suppress(OSError):
        names += [str(info[4][0]) for info in socket.getaddrinfo(hostname, None)]
    names += _interface_addresses()
    names += ["localhost", "127.0.0.1", "::1"]
    return list(dict.fromkeys(n for n in names if n))


def _interface_addresses() -> list[str]:
    """This machine's IPv4 addresses (Linux: from /proc; empty elsewhere)."""
    import socket

    found: list[str] = []
    try:
        with open("/proc/net/fib_trie") as f:
            lines = f.read().splitlines()
    except OSError:
        return found
    for i, line in enumerate(lines):
        if "/32 host LOCAL" in line and i > 0:
            address = lines[i - 1].split()[-1]
            try:
                socket.inet_aton(address)
            except OSError:
                continue
            found.append(address)
    return found
