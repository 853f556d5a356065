"""The PackML object served over OPC UA (asyncua), secured: a door that translates only.

Reads: every variable follows the controller's event stream. One task (the updater) takes
the events in order: a state change writes its own new state first, so a subscriber sees
every transition even when the next one follows at once, then every other variable from
the status snapshot as it stands. A 1 s tick keeps the times and the speed current.

Writes and calls: ``CmdChangeRequest = true`` (with ``CntrlCmd``, in the same write or
before), ``UnitModeChangeRequest = true`` (with ``UnitMode``) and the methods go through
the controller's ``command`` and ``set_mode``, as REST and the Modbus tags do. A refusal is
a Bad status (Bad_InvalidState for a command the state or the machine refuses,
Bad_OutOfRange for an unknown number) and its reason is in ``Status.CmdInvalidReason``;
nothing of a refused write is kept. Roles are checked before (bwsd.opcua.security).
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import logging
import os
import time
from collections.abc import Mapping
from datetime import UTC
from pathlib import Path
from typing import Any

from asyncua import Server, ua
from asyncua.common.callback import CallbackType, ServerItemCallback
from asyncua.common.utils import ServiceError

from bwsd.controller.facade import Controller
from bwsd.controller.packml import Command
from bwsd.controller.status import Event, InstructionDone, ProgramLoaded, StateChanged
from bwsd.errors import BwsdError
from bwsd.gate import Caller, Gate
from bwsd.gate import Refused as GateRefused
from bwsd.logs import Summary
from bwsd.opcua import space
from bwsd.opcua.security import (
    LoomUser,
    OpcUaError,
    Ruleset,
    TokenUsers,
    TrustFolder,
    application_uri,
    close_unsecured,
    current_user,
)
from bwsd.opcua.security import certificate as server_certificate
from bwsd.opcua.values import Tally, history_lines, status_values
from bwsd.tokens import Role, TokenStore

log = logging.getLogger(__name__)
REFRESH = Summary(log, "failed refreshes of the OPC UA variables")
WHO = "opcua"  # who gave a command, in the log (a write adds the user: asyncua 2.1 tells a
# write's user, not a method call's)
REASON = "by OPC UA"  # the reason given with Stop, Hold, Suspend and Abort
TICK = 1.0  # s between updates of the times and the speed
REVOKED_EVERY = 0.5  # s between checks of the open sessions' tokens
HISTORY = 10  # programs in Admin.ProgramHistory
_POLICIES = {
    ("Basic256Sha256", "SignAndEncrypt"): ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt,
    ("Basic256Sha256", "Sign"): ua.SecurityPolicyType.Basic256Sha256_Sign,
    (
        "Aes128Sha256RsaOaep",
        "SignAndEncrypt",
    ): ua.SecurityPolicyType.Aes128Sha256RsaOaep_SignAndEncrypt,
    ("Aes128Sha256RsaOaep", "Sign"): ua.SecurityPolicyType.Aes128Sha256RsaOaep_Sign,
    (
        "Aes256Sha256RsaPss",
        "SignAndEncrypt",
    ): ua.SecurityPolicyType.Aes256Sha256RsaPss_SignAndEncrypt,
    ("Aes256Sha256RsaPss", "Sign"): ua.SecurityPolicyType.Aes256Sha256RsaPss_Sign,
}


class Refused(Exception):
    """A request the controller refused: the Bad status and the reason."""

    def __init__(self, code: int, reason: str) -> None:
        super().__init__(reason)
        self.code = code


class OpcUaServer:
    """Serve a controller's PackML object on ``opc.tcp://host:port/bwsd``; port 0: any."""

    def __init__(
        self,
        controller: Controller,
        tokens: TokenStore,
        folder: Path,
        settings: Mapping[str, Any],
        gate: Gate | None = None,
    ) -> None:
        self.controller = controller
        self.tokens = tokens
        self.folder = folder  # the certificate, trusted/ and rejected/
        self.host = settings.get("host", "127.0.0.1")
        self.port = int(settings.get("port", 4840))
        self.policy = _POLICIES[
            (settings.get("policy", "Basic256Sha256"), settings.get("mode", "SignAndEncrypt"))
        ]
        self.allow_none = bool(settings.get("allow_none", False))
        self.anonymous = bool(settings.get("anonymous", False))
        self.server: Server | None = None
        self._space: space.Space | None = None
        self._tally = Tally(time.monotonic())
        self._events: asyncio.Queue[Event | None] = asyncio.Queue()
        self._updater: asyncio.Task[None] | None = None
        self._values: dict[str, Any] = {}  # as last written (and notified)
        self._live: dict[ua.NodeId, str] = {}  # status variables: read from the controller
        self._paths: dict[ua.NodeId, str] = {}  # every variable's path, by node id
        self._snapshot: dict[str, Any] | None = None  # the status values of this loop turn
        self.gate = gate or Gate(controller, tokens)

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"opc.tcp://{host}:{self.port}/bwsd"

    # ----- lifecycle -----
    async def start(self) -> None:
        """Make or load the certificate, build the address space, listen, follow the events."""
        if self.server is not None:
            raise RuntimeError(f"the OPC UA server on {self.url} is already running")
        cert = await asyncio.to_thread(server_certificate, self.folder, listening=self.host)
        trust = await asyncio.to_thread(TrustFolder, self.folder)
        server = Server(user_manager=TokenUsers(self.tokens, self.anonymous))  # type: ignore[arg-type]
        self.server = server  # from here on ``stop`` closes what a failed start left open
        await server.init()
        server.set_server_name("bwsd")
        await server.set_application_uri(application_uri())
        server.set_endpoint(self.url)
        await server.load_certificate(str(cert.cert))
        await server.load_private_key(str(cert.key))
        server.set_certificate_validator(trust)
        methods = space.Methods(
            self._method, self._set_mode_method, self._resume_method, self._load_method
        )
        self._space = await space.build(server, methods)
        self._paths = {node.nodeid: path for path, node in self._space.variables.items()}
        policies = [self.policy] + ([ua.SecurityPolicyType.NoSecurity] if self.allow_none else [])
        rules = Ruleset(space.needs(self._space.idx), self.tokens)
        server.set_security_policy(policies, rules)  # type: ignore[arg-type]
        self._user_access(server, rules)
        tokens: list[type] = [ua.UserNameIdentityToken]
        server.set_identity_tokens(tokens + ([ua.AnonymousIdentityToken] if self.anonymous else []))
        server.subscribe_server_callback(CallbackType.PreWrite, self._pre_write)
        server.subscribe_server_callback(CallbackType.PostWrite, self._post_write)
        await self._listen(server)
        if not self.allow_none:
            close_unsecured(server)
        self._tally = Tally(time.monotonic(), self.controller.status().state)
        self._events = asyncio.Queue()
        self._values = {}  # a new address space: nothing written to it yet
        await self._write("Command/UnitMode", int(self.controller.status().mode))
        self._read_live(server)
        await self._refresh()
        self.controller.events.subscribe(self._on_event)
        supervisor = self.controller.supervisor
        self._updater = supervisor.start("opcua", self._update_forever)
        supervisor.start("opcua sessions", self._drop_revoked, restart=True)
        log.info(
            "OPC UA on %s (%s%s), certificate %s",
            self.url,
            self.policy.name,
            ", None too" if self.allow_none else "",
            cert.thumbprint(),
        )

    def _read_live(self, server: Server) -> None:
        """A read of a status variable answers from the controller as it is at that moment
        (as REST and the Modbus tags do); the updater's writes only notify subscribers."""
        assert self._space is not None
        now = time.monotonic()
        for path in status_values(self.controller.status(), self._tally, now):
            nodeid = self._space.variables[path].nodeid
            self._live[nodeid] = path
            server.set_attribute_value_callback(nodeid, self._live_value)
            server.set_attribute_value_setter(nodeid, _notify_only)

    def _live_value(self, nodeid: ua.NodeId, attr: ua.AttributeIds) -> ua.DataValue:
        value = self._status_values()[self._live[nodeid]]
        path = self._live[nodeid]
        stamp = ua.DateTime.now(UTC)
        return ua.DataValue(
            ua.Variant(value, _KINDS[path]), SourceTimestamp=stamp, ServerTimestamp=stamp
        )

    def _status_values(self) -> dict[str, Any]:
        """The status variables' values from one status snapshot per read request: a PLC's
        Read of every tag is answered in one go, so the snapshot is kept until the event
        loop's next turn."""
        if self._snapshot is None:
            self._snapshot = status_values(self.controller.status(), self._tally, time.monotonic())
            asyncio.get_running_loop().call_soon(self._forget_snapshot)
        return self._snapshot

    def _forget_snapshot(self) -> None:
        self._snapshot = None

    def _user_access(self, server: Server, rules: Ruleset) -> None:
        """Each writable variable's UserAccessLevel and each method's UserExecutable are the
        reading user's: writable (callable) only for a role that may write (call) it; asyncua
        keeps one attribute for every user."""
        assert self._space is not None
        for tag in space.TAGS:
            if tag.writer is None:
                continue
            writer: Role = tag.writer

            def level(nodeid: ua.NodeId, attr: ua.AttributeIds, w: Role = writer) -> ua.DataValue:
                bits = ua.AccessLevel.CurrentRead.mask
                if rules.may(current_user(), w):
                    bits |= ua.AccessLevel.CurrentWrite.mask
                return ua.DataValue(ua.Variant(bits, ua.VariantType.Byte))

            nodeid = self._space.variables[tag.path].nodeid
            server.set_attribute_value_callback(nodeid, level, ua.AttributeIds.UserAccessLevel)
        for method, needs in space.needs(self._space.idx).items():
            if method in self._paths:
                continue  # a variable, done above

            def executable(
                nodeid: ua.NodeId, attr: ua.AttributeIds, n: Role = needs
            ) -> ua.DataValue:
                return ua.DataValue(
                    ua.Variant(rules.may(current_user(), n), ua.VariantType.Boolean)
                )

            server.set_attribute_value_callback(method, executable, ua.AttributeIds.UserExecutable)

    async def _drop_revoked(self) -> None:
        """Close, within REVOKED_EVERY, every session whose token was removed or whose role
        changed since its login: its next request would be refused anyway."""
        while True:
            await asyncio.sleep(REVOKED_EVERY)
            server = self.server
            if server is None or server.bserver is None:
                continue
            for client in list(server.bserver.clients):  # asyncua has no public list
                session = client.processor.session if client.processor is not None else None
                user = session.user if session is not None else None
                if isinstance(user, LoomUser) and not self.tokens_agree(user):
                    log.info(
                        "OPC UA: closed the session of %s: its token was removed or its "
                        "role changed",
                        user.name,
                    )
                    if client.transport is not None:
                        client.transport.close()

    def tokens_agree(self, user: LoomUser) -> bool:
        """The user's token is still known, with the role it logged in with."""
        if user.token is None:
            return True  # anonymous (only where the config allows it): no token to remove
        held = self.tokens.check(user.token)
        return held == (user.name, user.bwsd_role)

    async def _listen(self, server: Server) -> None:
        try:
            await server.start()
        except OSError as exc:
            why = os.strerror(exc.errno) if exc.errno else str(exc)
            raise OpcUaError(f"[opcua] cannot listen on {self.host}:{self.port}: {why}") from None
        bound = server.bserver
        if bound is not None and self.port == 0:
            self.port = bound.port
            for endpoint in server.iserver.endpoints:  # the URL clients see names the port
                endpoint.EndpointUrl = self.url

    async def stop(self) -> None:
        """Stop following the events, close every session and the port."""
        self.controller.events.unsubscribe(self._on_event)
        updater, self._updater = self._updater, None
        if updater is not None:
            self._events.put_nowait(None)
            with contextlib.suppress(asyncio.CancelledError):
                await updater
        server, self.server = self.server, None
        if server is not None:
            await server.stop()

    # ----- following the controller -----
    def _on_event(self, event: Event) -> None:
        self._events.put_nowait(event)

    async def _update_forever(self) -> None:
        """The updater: the events in order, and a tick for the clocks."""
        while True:
            try:
                event = await asyncio.wait_for(self._events.get(), TICK)
            except TimeoutError:
                await self._refresh_guarded(history=False)
                continue
            if event is None:
                return
            now = time.monotonic()
            if isinstance(event, StateChanged):
                self._tally.state_changed(event.new, now)
                await self._write("Status/StateCurrent", int(event.new), event.at)
            elif isinstance(event, InstructionDone):
                self._tally.instruction_done(now)
            if self._events.empty():  # a burst of events: the rest once, at its end
                await self._refresh_guarded(isinstance(event, ProgramLoaded | StateChanged))

    async def _refresh_guarded(self, history: bool) -> None:
        """A refresh that fails (the journal unreadable a moment) is logged; the next one
        tries again. Reads of the status variables do not depend on it."""
        try:
            await self._refresh(history)
        except Exception as exc:
            REFRESH.note("OPC UA: the variables could not be refreshed: %s", exc)

    async def _refresh(self, history: bool = True) -> None:
        """Write every variable that changed, from the controller as it stands now."""
        now = time.monotonic()
        values = status_values(self.controller.status(), self._tally, now)
        values.update(await self._twin_values())
        if history:
            records = await self.controller.history(HISTORY)
            values["Admin/ProgramHistory"] = history_lines(records)
        for path, value in values.items():
            await self._write(path, value)

    async def _twin_values(self) -> dict[str, Any]:
        """The twin's occupancy, take-up and contacts, and the matrix's size."""
        view = await self.controller.twin_view()
        return {
            "Machine/Rows": view.rows,
            "Machine/Cols": view.cols,
            "Machine/TwinOccupancy": view.occupancy,
            "Machine/TakeUp": view.takeup,
            "Machine/Contacts": view.contacts,
        }

    async def _write(self, path: str, value: Any, at: float | None = None) -> None:
        """Write (and notify) ``value`` at ``path`` unless it is there already; ``at``: when
        it became true."""
        if self._values.get(path, _UNSET) == value or self._space is None or not self.server:
            return
        self._values[path] = value
        stamp = ua.DateTime.fromtimestamp(at, UTC) if at is not None else None
        await self.server.write_attribute_value(
            self._space.variables[path].nodeid,
            ua.DataValue(ua.Variant(value, _KINDS[path]), SourceTimestamp=stamp),
        )

    # ----- commands: methods -----
    def _caller(self, user: Any) -> Caller:
        """The gate's caller for an asyncua user (its token checked again by the gate)."""
        if isinstance(user, LoomUser):
            role = None if user.token else user.bwsd_role
            return Caller("opcua", user.name or "?", user.token, role)
        return Caller("opcua", "?", None, None)

    def _method(self, command: Command) -> space.MethodCall:
        async def call(parent: ua.NodeId) -> ua.StatusCode | list[Any]:
            return await self._answer(self._command(command, self._caller(current_user())))

        return call

    async def _resume_method(self, parent: ua.NodeId) -> ua.StatusCode | list[Any]:
        caller = self._caller(current_user())
        return await self._answer(
            self._through(
                self.gate.command(caller, Command.START, reason=REASON, resume=True), "Resume"
            )
        )

    async def _load_method(
        self, parent: ua.NodeId, name: Any, text: Any
    ) -> ua.StatusCode | list[Any]:
        caller = self._caller(current_user())
        loaded: list[int] = []

        async def load() -> None:
            loaded.append(await self.gate.load(caller, _plain(name), _plain(text)))

        answer = await self._answer(self._through(load(), "LoadProgram"))
        if loaded:
            return [ua.Variant(loaded[0], ua.VariantType.UInt32)]
        return answer

    async def _set_mode_method(self, parent: ua.NodeId, mode: Any) -> ua.StatusCode | list[Any]:
        return await self._answer(self._mode(_plain(mode), self._caller(current_user())))

    async def _answer(self, request: Any) -> ua.StatusCode | list[Any]:
        try:
            await request
        except Refused as exc:
            return space.status(exc.code)
        return []

    async def _command(self, number: Any, caller: Caller) -> None:
        """Apply a PackML command through the gate; Refused when it or the controller refuses."""
        await self._through(self.gate.command(caller, number, reason=REASON), f"command {number}")

    async def _mode(self, number: Any, caller: Caller) -> None:
        await self._through(self.gate.set_mode(caller, number), f"mode {number}")

    async def _through(self, request: Any, what: str) -> None:
        try:
            await request
        except GateRefused as exc:
            await self._refused(Refused(_GATE_CODES[exc.kind], str(exc)))
        except BwsdError as exc:
            await self._refused(Refused(ua.StatusCodes.BadInvalidState, str(exc)))
        except Exception as exc:  # the client must still get an answer
            log.exception("OPC UA: %s failed", what)
            await self._refused(Refused(ua.StatusCodes.BadInternalError, f"{what} failed: {exc}"))
        await self._write("Status/CmdInvalid", False)
        await self._write("Status/CmdInvalidReason", "")

    async def _refused(self, refusal: Refused) -> None:
        log.info("OPC UA: refused: %s", refusal)  # a refusal is routine; a failure is an error
        await self._write("Status/CmdInvalid", True)
        await self._write("Status/CmdInvalidReason", str(refusal))
        raise refusal

    # ----- commands: the PackTags handshake -----
    async def _pre_write(self, event: ServerItemCallback, _: Any) -> None:
        """A client's write: check the types of the command variables written, and take a
        change request, before anything of the write is stored; a write refused here (a wrong
        type, a refused command) stores nothing and acts on nothing."""
        if self._space is None or not event.is_external:
            return
        written = {}
        for w in event.request_params.NodesToWrite:
            if w.AttributeId != ua.AttributeIds.Value or w.Value.Value is None:
                continue
            path = self._paths.get(w.NodeId)
            if path in _TYPES:
                w.Value = _typed(w.Value, path)  # Int16 taken as Int32, else refused
            written[w.NodeId] = w.Value.Value.Value
        pairs = (
            ("Command/CmdChangeRequest", "Command/CntrlCmd", self._command),
            ("Command/UnitModeChangeRequest", "Command/UnitMode", self._mode),
        )
        caller = self._caller(event.user)
        for request, number, apply in pairs:
            if written.get(self._id(request)) is True:
                wanted = written.get(self._id(number), self._values.get(number))
                try:
                    await apply(wanted, caller)
                except Refused as exc:
                    raise ServiceError(exc.code) from exc

    async def _post_write(self, event: ServerItemCallback, _: Any) -> None:
        """A request taken reads false again (the handshake's answer)."""
        if self._space is None or not event.is_external:
            return
        for w in event.request_params.NodesToWrite:
            for path in (
                "Command/CmdChangeRequest",
                "Command/UnitModeChangeRequest",
                "Command/CntrlCmd",
                "Command/UnitMode",
            ):
                if w.NodeId == self._id(path) and w.Value.Value is not None:
                    self._values[path] = w.Value.Value.Value
        await self._write("Command/CmdChangeRequest", False)
        await self._write("Command/UnitModeChangeRequest", False)

    def _id(self, path: str) -> ua.NodeId:
        assert self._space is not None
        return self._space.variables[path].nodeid


def _notify_only(node: Any, attr: ua.AttributeIds, value: ua.DataValue) -> None:
    """A status variable keeps no value: its reads ask the controller."""


# What a command variable takes: CntrlCmd and UnitMode are Int32, and take a PLC's INT
# (Int16) as the same number; the requests are Boolean. Any other type is refused before
# anything acts (Bad_TypeMismatch), as asyncua would refuse it after.
_NUMBERS = (ua.VariantType.Int32, ua.VariantType.Int16)
_TYPES = {
    "Command/CntrlCmd": _NUMBERS,
    "Command/UnitMode": _NUMBERS,
    "Command/CmdChangeRequest": (ua.VariantType.Boolean,),
    "Command/UnitModeChangeRequest": (ua.VariantType.Boolean,),
}
_GATE_CODES = {
    "type": ua.StatusCodes.BadTypeMismatch,
    "range": ua.StatusCodes.BadOutOfRange,
    "who": ua.StatusCodes.BadUserAccessDenied,
    "role": ua.StatusCodes.BadUserAccessDenied,
}


def _typed(value: ua.DataValue, path: str) -> ua.DataValue:
    """The written value, an Int16 number as the variable's Int32; ServiceError for a type
    the variable does not take."""
    variant = value.Value
    assert variant is not None
    if variant.VariantType not in _TYPES[path] or variant.is_array:
        log.info("OPC UA: refused a write of %s as %s", path, variant.VariantType.name)
        raise ServiceError(ua.StatusCodes.BadTypeMismatch)
    if variant.VariantType is ua.VariantType.Int16:
        return dataclasses.replace(value, Value=ua.Variant(variant.Value, ua.VariantType.Int32))
    return value


def _plain(value: Any) -> Any:
    """A method argument's value (asyncua may pass a Variant)."""
    return value.Value if isinstance(value, ua.Variant) else value


_UNSET = object()
_KINDS = {tag.path: tag.kind for tag in space.TAGS}
