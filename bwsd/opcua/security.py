"""OPC UA security: the server's certificate, trusted clients, users and what each role may do.

- The server certificate and key live in the state folder (``opcua/``), made on first start
  (RSA 2048, self-signed, valid for a year, the application URI and host in its names).
- A client's certificate must be in the trust folder; one that is not is refused
  (Bad_CertificateUntrusted) and copied into ``rejected/``, where an integrator finds it to
  move into ``trusted/``. The trust folder is read at every new session.
- Users are the API's tokens: user name = the token's name, password = the token; the
  token's role is the user's (viewer reads, operator commands, admin changes the mode).
- Nobody edits the address space; a write or a call needs the role of every node it names.
"""

from __future__ import annotations

import asyncio
import contextlib
import contextvars
import hashlib
import ipaddress
import logging
import socket
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from asyncua import ua
from asyncua.common.utils import Buffer, ServiceError
from asyncua.crypto import cert_gen
from asyncua.crypto.permission_rules import USER_TYPES, PermissionRuleset, User, UserRole
from asyncua.crypto.security_policies import SecurityPolicyFactory, SecurityPolicyNone
from asyncua.crypto.truststore import TrustStore
from asyncua.crypto.validator import CertificateValidator, CertificateValidatorOptions
from asyncua.ua.ua_binary import struct_from_binary
from cryptography import x509
from cryptography.hazmat.primitives.serialization import Encoding
from cryptography.x509.oid import ExtendedKeyUsageOID

from bwsd.errors import BwsdError
from bwsd.logs import Summary
from bwsd.opcua.space import standard_id, status
from bwsd.paths import write_private
from bwsd.tokens import RANK, Role, TokenStore

log = logging.getLogger(__name__)
CERT_FILE = "server-cert.der"
KEY_FILE = "server-key.pem"
CERT_DAYS = 365
REFUSED_LOGIN = Summary(log, "refused OPC UA logins")
REFUSED_CERT = Summary(log, "refused OPC UA client certificates")

_WRITE = standard_id(ua.ObjectIds.WriteRequest_Encoding_DefaultBinary)
_CALL = standard_id(ua.ObjectIds.CallRequest_Encoding_DefaultBinary)
_ALLOWED = frozenset(standard_id(t) for t in USER_TYPES)


class OpcUaError(BwsdError):
    """The OPC UA server cannot start, or its certificate cannot be made or read."""


def application_uri(host: str | None = None) -> str:
    """The server's application URI: in its certificate and in its endpoints."""
    return f"urn:{host or socket.gethostname()}:bwsd"


@dataclass(frozen=True)
class Certificate:
    """The server's certificate and key files, and what a client checks of them."""

    cert: Path
    key: Path

    def load(self) -> x509.Certificate:
        return x509.load_der_x509_certificate(self.cert.read_bytes())

    def thumbprint(self) -> str:
        """SHA-1 of the DER certificate, as OPC UA clients show it (hex, colon-separated)."""
        digest = hashlib.sha1(self.cert.read_bytes(), usedforsecurity=False).hexdigest()
        return ":".join(digest[i : i + 2] for i in range(0, len(digest), 2)).upper()

    def describe(self) -> str:
        cert = self.load()
        return (
            f"certificate {self.cert}\n  thumbprint (SHA-1) {self.thumbprint()}\n"
            f"  subject {cert.subject.rfc4514_string()}\n"
            f"  valid {cert.not_valid_before_utc:%Y-%m-%d} to "
            f"{cert.not_valid_after_utc:%Y-%m-%d}"
        )


def certificate(folder: Path, *, renew: bool = False, listening: str = "127.0.0.1") -> Certificate:
    """The server certificate in ``folder``, made when missing, when ``renew``, or when it
    does not name the address the server listens on (``listening``)."""
    found = Certificate(folder / CERT_FILE, folder / KEY_FILE)
    if found.cert.exists() and found.key.exists() and not renew:
        if _names_host(found, listening):
            return found
        log.warning(
            "OPC UA: the server certificate does not name %s, where the server listens: "
            "made anew (clients that trusted the old one must trust the new one)",
            listening,
        )
    try:
        folder.mkdir(mode=0o700, parents=True, exist_ok=True)
        key = cert_gen.generate_private_key()
        host = socket.gethostname()
        cert = cert_gen.generate_self_signed_app_certificate(
            key,
            f"bwsd@{host}",
            {"organizationName": "bwsd"},
            _names(host, listening),
            [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH],
            days=CERT_DAYS,
        )
        write_private(found.key, cert_gen.dump_private_key_as_pem(key))
        found.cert.write_bytes(cert.public_bytes(Encoding.DER))
    except OSError as exc:
        raise OpcUaError(f"{folder}: cannot write the server certificate: {exc}") from exc
    log.info("OPC UA server certificate made: %s", found.thumbprint())
    return found


def _names(host: str, listening: str) -> list[x509.GeneralName]:
    """The certificate's names: the application URI, the machine's name, localhost, the
    loopback addresses, and the address the server listens on (on every address: the
    machine's own addresses)."""
    names: list[x509.GeneralName] = [
        x509.UniformResourceIdentifier(application_uri(host)),
        x509.DNSName(host),
        x509.DNSName("localhost"),
    ]
    addresses = {"127.0.0.1", "::1"}
    if listening in ("", "0.0.0.0", "::"):
        with contextlib.suppress(OSError):
            addresses |= {str(info[4][0]) for info in socket.getaddrinfo(host, None)}
    else:
        addresses.add(listening)
    for address in sorted(addresses):
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(address.split("%", 1)[0])))
        except ValueError:
            if address not in (host, "localhost"):
                names.append(x509.DNSName(address))
    return names


def _names_host(found: Certificate, listening: str) -> bool:
    """Whether the certificate names ``listening`` (a wildcard needs nothing more)."""
    if listening in ("", "0.0.0.0", "::"):
        return True
    try:
        alt = found.load().extensions.get_extension_for_class(x509.SubjectAlternativeName)
    except (x509.ExtensionNotFound, ValueError):
        return False
    try:
        return ipaddress.ip_address(listening) in alt.value.get_values_for_type(x509.IPAddress)
    except ValueError:
        return listening in alt.value.get_values_for_type(x509.DNSName)


# ----- users -----
@dataclass
class LoomUser(User):
    """An asyncua user carrying the bwsd role it logged in with and its token, checked again
    at every write and call (asyncua's own role stays User: no admin)."""

    bwsd_role: Role = "viewer"
    token: str | None = None  # None: anonymous


# The user of the request being served: set where asyncua checks a request's permissions,
# read by the methods (asyncua does not tell a method call's user) and by the per-user
# access levels, in the same task.
_CURRENT: contextvars.ContextVar[LoomUser | None] = contextvars.ContextVar(
    "opcua_user", default=None
)


def current_user() -> LoomUser | None:
    """The user whose request is being served (None outside a request)."""
    return _CURRENT.get()


class TokenUsers:
    """asyncua's user manager on the API's token store."""

    def __init__(self, tokens: TokenStore, anonymous: bool) -> None:
        self.tokens = tokens
        self.anonymous = anonymous

    def get_user(
        self,
        iserver: Any,
        username: str | None = None,
        password: str | None = None,
        certificate: Any = None,
    ) -> User | None:
        if username is None:  # anonymous (X509 user tokens are not offered)
            if self.anonymous:
                return LoomUser(UserRole.User, "anonymous", "viewer")
            REFUSED_LOGIN.note("OPC UA: refused an anonymous session")
            return None
        holder = self.tokens.check(password or "")
        if holder is None or holder[0] != username:
            REFUSED_LOGIN.note("OPC UA: refused user %r: unknown name or token", username)
            return None
        log.info("OPC UA: user %s (%s) logged in", holder[0], holder[1])
        return LoomUser(UserRole.User, holder[0], holder[1], password)


def role_of(user: Any) -> Role | None:
    return user.bwsd_role if isinstance(user, LoomUser) else None


class Ruleset(PermissionRuleset):
    """Reads for every user; a write or a call needs the role of each node it names, the
    role the user's token has now (a token removed, or demoted, no longer counts)."""

    def __init__(self, needs: dict[ua.NodeId, Role], tokens: TokenStore | None = None) -> None:
        self.needs = needs
        self.tokens = tokens

    def check_validity(self, user: Any, action_type_id: Any, body: Any) -> bool:
        _CURRENT.set(user if isinstance(user, LoomUser) else None)
        if action_type_id not in _ALLOWED:
            return False  # the address space is never edited from outside
        targets = self._targets(action_type_id, body)
        return all(self.may(user, self.needs.get(t, "admin")) for t in targets)

    def may(self, user: Any, needs: Role) -> bool:
        """Whether ``user`` holds ``needs`` or above now."""
        role = self.role_now(user)
        return role is not None and RANK[role] >= RANK[needs]

    def role_now(self, user: Any) -> Role | None:
        """The user's role as its token says now (the login's for an anonymous one)."""
        if not isinstance(user, LoomUser):
            return None
        if user.token is None or self.tokens is None:
            return user.bwsd_role
        held = self.tokens.check(user.token)
        return held[1] if held is not None and held[0] == user.name else None

    @staticmethod
    def _targets(action: ua.NodeId, body: Buffer) -> list[ua.NodeId]:
        if action == _WRITE:
            params = struct_from_binary(ua.WriteParameters, body.copy())
            return [w.NodeId for w in params.NodesToWrite]
        if action == _CALL:
            calls = struct_from_binary(ua.CallParameters, body.copy())
            return [m.MethodId for m in calls.MethodsToCall]
        return []


class DiscoveryOnly(PermissionRuleset):
    """For a channel without security that the config does not offer: nothing but finding
    the endpoints (which needs no session). asyncua 2.1 opens such a channel whatever the
    policies, and would serve a session over it."""

    def check_validity(self, user: Any, action_type_id: Any, body: Any) -> bool:
        return False


def close_unsecured(server: Any) -> None:
    """Put ``DiscoveryOnly`` on channels without security (after ``server.start()``).

    The listener picks a channel's policy from the server's policy list, which it shares;
    asyncua has no public call for this, hence the private list.
    """
    none = SecurityPolicyFactory(  # type: ignore[no-untyped-call]
        SecurityPolicyNone, ua.MessageSecurityMode.None_, permission_ruleset=DiscoveryOnly()
    )
    server._policies.append(none)


# ----- client certificates -----
class TrustFolder:
    """Validates client certificates against ``trusted/``; keeps refused ones in ``rejected/``."""

    def __init__(self, folder: Path) -> None:
        self.trusted = folder / "trusted"
        self.rejected = folder / "rejected"
        for made in (self.trusted, self.rejected):
            made.mkdir(mode=0o700, parents=True, exist_ok=True)

    async def __call__(self, cert: x509.Certificate, app: ua.ApplicationDescription) -> None:
        if not any(self.trusted.iterdir()):  # asyncua cannot build a store from none
            await self._refuse(cert, app, ServiceError(ua.StatusCodes.BadCertificateUntrusted))
        store = TrustStore([self.trusted], [])
        await store.load()
        options = (
            CertificateValidatorOptions.TRUSTED_VALIDATION | CertificateValidatorOptions.PEER_CLIENT
        )
        try:
            await CertificateValidator(options, store).validate(cert, app)
        except ServiceError as exc:
            await self._refuse(cert, app, exc)

    async def _refuse(
        self, cert: x509.Certificate, app: ua.ApplicationDescription, exc: ServiceError
    ) -> None:
        """Log the refusal, keep an untrusted certificate in ``rejected/``, raise ``exc``."""
        name = status(exc.code).name
        der = cert.public_bytes(Encoding.DER)
        thumb = hashlib.sha1(der, usedforsecurity=False).hexdigest()
        REFUSED_CERT.note(
            "OPC UA: refused client %s (certificate %s): %s", app.ApplicationUri, thumb, name
        )
        if exc.code == ua.StatusCodes.BadCertificateUntrusted:
            await asyncio.to_thread(self._keep, thumb, der)
        raise exc

    def _keep(self, thumb: str, der: bytes) -> None:
        try:
            (self.rejected / f"{thumb}.der").write_bytes(der)
        except OSError as exc:
            log.warning("OPC UA: cannot keep a rejected certificate: %s", exc)
