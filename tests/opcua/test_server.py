"""An asyncua client plays the line controller over loopback: an encrypted session (Basic256Sha256,
Sign & Encrypt) with a certificate the server trusts, and a user from the API's tokens."""

from __future__ import annotations

import asyncio
import time
from typing import Any

import pytest
from asyncua import Client, ua
from asyncua.common.utils import create_nonce
from asyncua.ua.uaerrors import UaStatusCodeError

from bwsd.controller.packml import Command, State, UnitMode
from bwsd.controller.status import StateChanged, StopCause
from bwsd.opcua.space import NAMESPACE, TAGS, node_id
from tests.opcua.conftest import TEXT, client_cert, loom, rig, run, session, var
from tests.support.controller import mode_now, state_now

pytestmark = pytest.mark.slow  # every test here is in the slow tier

MAINTENANCE = ua.Variant(int(UnitMode.MAINTENANCE), ua.VariantType.Int32)
EXPECTED_RUN = [
    State.RESETTING,
    State.IDLE,
    State.STARTING,
    State.EXECUTE,
    State.COMPLETING,
    State.COMPLETE,
]


class Changes:
    """An asyncua subscription handler that keeps every value it is told of."""

    def __init__(self) -> None:
        self.values: list[Any] = []
        self.stamps: list[float] = []  # each value's source time stamp (epoch s)

    def datachange_notification(self, node: Any, value: Any, data: Any) -> None:
        self.values.append(value)
        self.stamps.append(data.monitored_item.Value.SourceTimestamp.timestamp())

    async def until(self, done: Any, seconds: float = 30.0) -> list[Any]:
        deadline = time.monotonic() + seconds
        while not done(self.values):
            assert time.monotonic() < deadline, f"still {self.values}"
            await asyncio.sleep(0.01)
        return self.values


async def read(client: Any, path: str) -> Any:
    return await (await var(client, path)).read_value()


async def until_state(client: Any, state: State, seconds: float = 30.0) -> None:
    deadline = time.monotonic() + seconds
    while (now := await read(client, "Status/StateCurrent")) != state:
        assert time.monotonic() < deadline, f"still in {State(now).label}"
        await asyncio.sleep(0.02)


def test_the_packml_object_is_browsed_with_types_units_and_methods(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path) as r, r.session("viewer") as client:
            idx = await client.get_namespace_index(NAMESPACE)
            root = await loom(client)
            children = {(await c.read_browse_name()).Name: c for c in await root.get_children()}
            assert {"Status", "Command", "Admin", "Machine"} <= set(children)
            assert {c.label for c in Command} | {"SetUnitMode"} <= set(children)
            status = {
                (await c.read_browse_name()).Name for c in await children["Status"].get_children()
            }
            assert {"StateCurrent", "UnitModeCurrent", "CurMachSpeed", "CurrentLine"} <= status
            state = await var(client, "Status/StateCurrent")
            assert state.nodeid == node_id(idx, "Status/StateCurrent")
            assert await state.read_data_type_as_variant_type() == ua.VariantType.Int32
            assert await state.read_value() == State.STOPPED
            speed = await var(client, "Status/CurMachSpeed")
            units = await (await speed.get_child("0:EngineeringUnits")).read_value()
            assert units.DisplayName.Text == "1/min"
            for tag in TAGS:  # every documented tag is there, with its type
                node = await var(client, tag.path)
                assert await node.read_data_type_as_variant_type() == tag.kind, tag.path
            cmd = await var(client, "Command/CntrlCmd")
            assert ua.AccessLevel.CurrentWrite in await cmd.get_access_level()
            assert ua.AccessLevel.CurrentWrite not in await state.get_access_level()

    run(scenario())


def test_a_subscription_sees_every_transition_of_a_run_to_complete(slow_mock, tmp_path):
    async def scenario() -> None:
        async with rig(slow_mock, tmp_path) as r, r.session("operator") as client:
            published: list[StateChanged] = []
            r.controller.events.subscribe(
                lambda e: published.append(e) if isinstance(e, StateChanged) else None
            )
            changes = Changes()
            sub = await client.create_subscription(20, changes)
            await sub.subscribe_data_change(await var(client, "Status/StateCurrent"), queuesize=100)
            await changes.until(lambda v: v == [State.STOPPED])
            await r.controller.load("braid.bws", TEXT)
            assert r.controller.twin is not None
            root = await loom(client)
            idx = await client.get_namespace_index(NAMESPACE)
            await root.call_method(f"{idx}:Reset")
            await root.call_method(f"{idx}:Start")
            seen = await changes.until(lambda v: v[-1:] == [State.COMPLETE])
            assert [e.new for e in published] == EXPECTED_RUN
            assert seen == [State.STOPPED, *EXPECTED_RUN]
            # each notification carries the time of the change itself, not of its sending
            assert changes.stamps[1:] == pytest.approx([e.at for e in published], abs=1e-6)
            assert await read(client, "Status/InstructionsDone") == 15
            assert await read(client, "Admin/ProdGoodCount") == 1
            assert await read(client, "Machine/Contacts") == r.controller.twin.contact_count

    run(scenario())


def test_cntrl_cmd_and_cmd_change_request_drive_a_program(slow_mock, tmp_path):
    async def scenario() -> None:
        async with rig(slow_mock, tmp_path) as r, r.session("operator") as client:
            await r.controller.load("braid.bws", TEXT)
            cmd = await var(client, "Command/CntrlCmd")
            request = await var(client, "Command/CmdChangeRequest")
            # a PLC's way: the command first, then the request
            await cmd.write_value(ua.Variant(int(Command.RESET), ua.VariantType.Int32))
            assert r.controller.packml.state is State.STOPPED  # CntrlCmd alone does nothing
            await request.write_value(True)
            assert state_now(r.controller) is State.IDLE
            assert await request.read_value() is False  # taken: reads false again
            # both in one write request
            await client.write_values(
                [cmd, request],
                [ua.Variant(int(Command.START), ua.VariantType.Int32), True],
            )
            assert state_now(r.controller) is State.EXECUTE
            await cmd.write_value(ua.Variant(int(Command.HOLD), ua.VariantType.Int32))
            await request.write_value(True)
            assert state_now(r.controller) is State.HELD
            assert r.controller.packml.reason == "by OPC UA"
            await until_state(client, State.HELD)
            assert await read(client, "Admin/StopReason/ID") == StopCause.OPERATOR
            assert await read(client, "Admin/StopReason/Message") == "by OPC UA"
            idx = await client.get_namespace_index(NAMESPACE)
            await (await loom(client)).call_method(f"{idx}:Unhold")
            await until_state(client, State.COMPLETE)
            assert r.controller.index == 15

    run(scenario())


def test_unit_mode_changes_need_an_admin(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path) as r:
            async with r.session("operator") as client:
                idx = await client.get_namespace_index(NAMESPACE)
                with pytest.raises(ua.uaerrors.BadUserAccessDenied):
                    await (await loom(client)).call_method(f"{idx}:SetUnitMode", MAINTENANCE)
                assert r.controller.packml.mode is UnitMode.PRODUCTION
            async with r.session("admin") as client:
                await (await loom(client)).call_method(f"{idx}:SetUnitMode", MAINTENANCE)
                assert mode_now(r.controller) is UnitMode.MAINTENANCE
                mode = await var(client, "Command/UnitMode")
                await mode.write_value(ua.Variant(3, ua.VariantType.Int32))
                await (await var(client, "Command/UnitModeChangeRequest")).write_value(True)
                assert mode_now(r.controller) is UnitMode.MANUAL
                assert await read(client, "Status/UnitModeCurrent") == UnitMode.MANUAL
            for _ in range(500):  # the journal's writer records who, in order, soon after
                by = [e.data["by"] for e in r.journal.events(0, 100) if e.kind == "mode"]
                if len(by) == 2:
                    break
                await asyncio.sleep(0.01)
            assert by == ["opcua:admin", "opcua:admin"]  # a method's caller and a writer

    run(scenario())


def test_a_viewer_reads_and_is_refused_every_command(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path) as r, r.session("viewer") as client:
            assert await read(client, "Status/StateCurrent") == State.STOPPED
            idx = await client.get_namespace_index(NAMESPACE)
            with pytest.raises(ua.uaerrors.BadUserAccessDenied):
                await (await loom(client)).call_method(f"{idx}:Reset")
            cmd = await var(client, "Command/CntrlCmd")
            with pytest.raises(ua.uaerrors.BadUserAccessDenied):
                await client.write_values(
                    [cmd, await var(client, "Command/CmdChangeRequest")],
                    [ua.Variant(int(Command.RESET), ua.VariantType.Int32), True],
                )
            assert r.controller.packml.state is State.STOPPED
            assert await cmd.read_value() == 0  # nothing of the refused write was kept
            with pytest.raises(ua.uaerrors.BadUserAccessDenied):  # nor is a status writable
                await (await var(client, "Status/StateCurrent")).write_value(
                    ua.Variant(6, ua.VariantType.Int32)
                )

    run(scenario())


def test_a_command_refused_in_the_wrong_state_says_why(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path) as r, r.session("operator") as client:
            idx = await client.get_namespace_index(NAMESPACE)
            root = await loom(client)
            with pytest.raises(ua.uaerrors.BadInvalidState):
                await root.call_method(f"{idx}:Unhold")
            assert await read(client, "Status/CmdInvalid") is True
            reason = await read(client, "Status/CmdInvalidReason")
            assert reason == (
                "Unhold is not accepted in state Stopped (accepted there: Reset, Abort)"
            )
            await root.call_method(f"{idx}:Reset")  # the next accepted one clears it
            assert (await read(client, "Status/CmdInvalid"), r.controller.packml.state) == (
                False,
                State.IDLE,
            )
            cmd = await var(client, "Command/CntrlCmd")
            request = await var(client, "Command/CmdChangeRequest")
            with pytest.raises(ua.uaerrors.BadInvalidState):  # Start: no program is loaded
                await client.write_values(
                    [cmd, request], [ua.Variant(int(Command.START), ua.VariantType.Int32), True]
                )
            assert await read(client, "Status/CmdInvalidReason") == "no program is loaded"
            assert await cmd.read_value() == 0  # the refused write kept nothing
            with pytest.raises(ua.uaerrors.BadOutOfRange):
                await client.write_values(
                    [cmd, request], [ua.Variant(42, ua.VariantType.Int32), True]
                )
            assert r.controller.packml.state is State.IDLE

    run(scenario())


def test_an_untrusted_certificate_is_refused_and_kept_for_the_integrator(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path) as r:
            stranger = client_cert(tmp_path / "stranger", "stranger")
            with pytest.raises(UaStatusCodeError) as refused:
                async with r.session("operator", cert=stranger):
                    pass
            assert refused.value.code == ua.StatusCodes.BadCertificateUntrusted
            kept = list((r.folder / "rejected").iterdir())
            assert [p.read_bytes() for p in kept] == [stranger.cert.read_bytes()]
            (r.folder / "trusted" / "stranger.der").write_bytes(kept[0].read_bytes())
            async with r.session("operator", cert=stranger) as client:  # trusted now
                assert await read(client, "Status/StateCurrent") == State.STOPPED

    run(scenario())


def test_anonymous_sessions_wrong_passwords_and_no_security_are_refused(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path) as r:
            with pytest.raises(UaStatusCodeError) as anonymous:
                async with session(r.server.url, r.cert):
                    pass
            assert anonymous.value.code == ua.StatusCodes.BadIdentityTokenRejected
            with pytest.raises(ua.uaerrors.BadUserAccessDenied):
                async with session(r.server.url, r.cert, "operator", r.users["admin"]):
                    pass  # another user's token is not this user's password
            with pytest.raises(Exception) as plain:
                async with session(r.server.url, None, "operator", r.users["operator"]):
                    pass
            assert "SecurityPolicy" in repr(plain.value) or "Bad" in repr(plain.value)
            assert r.controller.packml.state is State.STOPPED

    run(scenario())


def test_anonymous_reads_when_the_config_allows_and_still_commands_nothing(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path, anonymous=True) as r, session(r.server.url, r.cert) as c:
            assert await read(c, "Status/StateCurrent") == State.STOPPED
            idx = await c.get_namespace_index(NAMESPACE)
            with pytest.raises(ua.uaerrors.BadUserAccessDenied):
                await (await loom(c)).call_method(f"{idx}:Reset")
            assert r.controller.packml.state is State.STOPPED

    run(scenario())


async def unsecured_session(url: str, user: str, password: str) -> Any:
    """What a hostile client can do by hand: a session over a channel with no security at
    all, though the server offers no such endpoint, the password in clear."""
    client = Client(url, timeout=5)
    await client.connect_socket()
    await client.send_hello()
    await client.open_secure_channel()  # None: allowed, for GetEndpoints (OPC 10000-4)
    params = ua.CreateSessionParameters(
        ClientDescription=ua.ApplicationDescription(
            ApplicationUri="urn:intruder", ApplicationType=ua.ApplicationType.Client
        ),
        EndpointUrl=url,
        SessionName="intruder",
        ClientNonce=create_nonce(32),
        RequestedSessionTimeout=60000,
        MaxResponseMessageSize=0,
    )
    await client.uaclient.create_session(params)
    token = ua.UserNameIdentityToken(
        PolicyId="username", UserName=user, Password=password.encode(), EncryptionAlgorithm=None
    )
    await client.uaclient.activate_session(ua.ActivateSessionParameters(UserIdentityToken=token))
    return client


def test_a_session_over_an_unsecured_channel_can_do_nothing(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path) as r:
            client = await unsecured_session(r.server.url, "operator", r.users["operator"])
            try:
                idx = await client.uaclient.read_attributes(
                    [ua.NodeId(ua.Int32(ua.ObjectIds.Server_NamespaceArray))], ua.AttributeIds.Value
                )
                pytest.fail(f"read over an unsecured channel: {idx}")
            except ua.uaerrors.BadUserAccessDenied:
                pass
            idx = 0
            async with r.session("viewer") as secured:
                idx = await secured.get_namespace_index(NAMESPACE)
            call = ua.CallMethodRequest(ObjectId=node_id(idx, ""), MethodId=node_id(idx, "Reset"))
            with pytest.raises(ua.uaerrors.BadUserAccessDenied):
                await client.uaclient.call([call])
            assert r.controller.packml.state is State.STOPPED
            client.disconnect_socket()

    run(scenario())


def test_allow_none_offers_an_unsecured_endpoint_with_the_same_roles(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path, allow_none=True) as r:
            async with session(r.server.url, None, "viewer", r.users["viewer"]) as plain:
                assert await read(plain, "Status/StateCurrent") == State.STOPPED
                idx = await plain.get_namespace_index(NAMESPACE)
                with pytest.raises(ua.uaerrors.BadUserAccessDenied):
                    await (await loom(plain)).call_method(f"{idx}:Reset")
            async with r.session("operator") as secured:  # the secured endpoint is still there
                await (await loom(secured)).call_method(f"{idx}:Reset")
            assert r.controller.packml.state is State.IDLE

    run(scenario())


def test_an_aborted_part_resumes_by_the_resume_method(slow_mock, tmp_path):
    async def scenario() -> None:
        async with rig(slow_mock, tmp_path) as r, r.session("operator") as client:
            await r.controller.load("braid.bws", TEXT)
            root = await loom(client)
            idx = await client.get_namespace_index(NAMESPACE)
            await root.call_method(f"{idx}:Reset")
            await root.call_method(f"{idx}:Start")
            while r.controller.index < 2:
                await asyncio.sleep(0.01)
            await root.call_method(f"{idx}:Abort")
            await until_state(client, State.ABORTED)
            assert await read(client, "Status/Resumable") is True
            await root.call_method(f"{idx}:Clear")
            await root.call_method(f"{idx}:Reset")
            with pytest.raises(ua.UaStatusCodeError):
                await root.call_method(f"{idx}:Start")  # a plain Start: refused
            await root.call_method(f"{idx}:Resume")
            await until_state(client, State.COMPLETE)
            assert r.controller.index == 15 and r.journal.program(1).outcome == "complete"

    run(scenario())
