"""The OPC UA door through the gate: a wire type is checked before anything acts, roles are
those of the tokens now, and what an integrator needs (a fresh install's trust folder, fixed
node ids, arrays, access levels per user, loading a program)."""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import socket
import sys
import time
from typing import Any

import pytest
from asyncua import ua
from asyncua.ua.uaerrors import UaStatusCodeError
from cryptography import x509

from bwsd.controller.packml import Command, State, UnitMode
from bwsd.opcua.security import CERT_FILE
from bwsd.opcua.space import NAMESPACE, TAGS
from bwsd.opcua.values import requested
from tests.opcua.conftest import TEXT, loom, rig, run, var
from tests.opcua.test_server import read
from tests.support.controller import mode_now

V = ua.VariantType


@pytest.mark.slow
@pytest.mark.parametrize(
    ("kind", "acts"),
    [(V.Int32, True), (V.Int16, True), (V.Double, False), (V.UInt32, False), (V.String, False)],
)
def test_a_command_written_as_a_wrong_type_acts_on_nothing(mock, tmp_path, kind, acts):
    """CntrlCmd as a PLC's INT (Int16) is the same number as Int32; any other type is
    refused (Bad_TypeMismatch) before the command runs: the loom does not move."""

    async def scenario() -> None:
        async with rig(mock, tmp_path) as r, r.session("operator") as client:
            await r.controller.load("braid.bws", TEXT)
            value = "1" if kind is V.String else int(Command.RESET)
            cmd, request = (
                await var(client, "Command/CntrlCmd"),
                await var(client, "Command/CmdChangeRequest"),
            )
            if acts:
                await client.write_values([cmd, request], [ua.Variant(value, kind), True])
                assert r.controller.packml.state is State.IDLE
                assert await read(client, "Command/CntrlCmd") == int(Command.RESET)
            else:
                with pytest.raises(UaStatusCodeError) as refused:
                    await client.write_values([cmd, request], [ua.Variant(value, kind), True])
                assert refused.value.code == ua.StatusCodes.BadTypeMismatch
                assert r.controller.packml.state is State.STOPPED  # nothing ran
                assert await read(client, "Command/CmdChangeRequest") is False
                with pytest.raises(UaStatusCodeError) as boolean:  # a request must be Boolean
                    await request.write_value(ua.Variant(1, V.Int32))
                assert boolean.value.code == ua.StatusCodes.BadTypeMismatch
                assert r.controller.packml.state is State.STOPPED

    run(scenario())


@pytest.mark.slow
def test_a_unit_mode_sent_as_int16_or_wrong_acts_as_its_number_or_not_at_all(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path) as r, r.session("admin") as client:
            root = await loom(client)
            idx = await client.get_namespace_index(NAMESPACE)
            await root.call_method(f"{idx}:SetUnitMode", ua.Variant(2, V.Int16))
            assert r.controller.packml.mode is UnitMode.MAINTENANCE
            for wrong in (ua.Variant(2.0, V.Double), ua.Variant(7, V.Int32)):
                with pytest.raises(UaStatusCodeError):
                    await root.call_method(f"{idx}:SetUnitMode", wrong)
            mode, request = (
                await var(client, "Command/UnitMode"),
                await var(client, "Command/UnitModeChangeRequest"),
            )
            with pytest.raises(UaStatusCodeError) as refused:
                await client.write_values([mode, request], [ua.Variant(3.0, V.Double), True])
            assert refused.value.code == ua.StatusCodes.BadTypeMismatch
            assert r.controller.packml.mode is UnitMode.MAINTENANCE
            await client.write_values([mode, request], [ua.Variant(3, V.Int16), True])
            assert mode_now(r.controller) is UnitMode.MANUAL

    run(scenario())


@pytest.mark.slow
def test_a_removed_token_ends_its_open_session_and_its_commands(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path) as r:
            client_ctx = r.session("operator")
            client = await client_ctx.__aenter__()
            try:
                idx = await client.get_namespace_index(NAMESPACE)
                root = await loom(client)
                r.tokens.remove("operator")
                removed = time.monotonic()
                with pytest.raises(UaStatusCodeError):  # refused at once: the role is now's
                    await root.call_method(f"{idx}:Reset")
                assert r.controller.packml.state is State.STOPPED
                while True:  # and the session is closed by the server soon after
                    try:
                        await client.read_values([await var(client, "Status/StateCurrent")])
                    except (TimeoutError, ConnectionError, UaStatusCodeError, OSError):
                        break
                    assert time.monotonic() - removed < 5, "the session stayed open"
                    await asyncio.sleep(0.05)
            finally:
                with contextlib.suppress(Exception):
                    await client_ctx.__aexit__(None, None, None)

    run(scenario())


@pytest.mark.slow
def test_a_fresh_install_follows_the_documented_trust_steps(mock, tmp_path):
    """docs/opcua.md, literally: with trusted/ empty a new client is refused as untrusted
    (not an internal error) and kept in rejected/; moved to trusted/, it connects."""

    async def scenario() -> None:
        async with rig(mock, tmp_path, trusted=False) as r:
            assert list((r.folder / "trusted").iterdir()) == []
            with pytest.raises(UaStatusCodeError) as refused:
                async with r.session("operator"):
                    pass
            assert refused.value.code == ua.StatusCodes.BadCertificateUntrusted
            [kept] = list((r.folder / "rejected").iterdir())
            assert kept.read_bytes() == r.cert.cert.read_bytes()
            kept.rename(r.folder / "trusted" / kept.name)  # the integrator's step
            async with r.session("operator") as client:
                assert await read(client, "Status/StateCurrent") == State.STOPPED
            (r.folder / "trusted" / kept.name).unlink()  # the last one removed: refused again
            with pytest.raises(UaStatusCodeError) as again:
                async with r.session("operator"):
                    pass
            assert again.value.code == ua.StatusCodes.BadCertificateUntrusted

    run(scenario())


@pytest.mark.slow
def test_node_ids_arrays_and_what_each_user_may_write(mock, tmp_path):
    async def scenario() -> None:
        async with (
            rig(mock, tmp_path) as r,
            r.session("viewer") as viewer,
            r.session("operator") as operator,
        ):
            idx = await viewer.get_namespace_index(NAMESPACE)
            node = viewer.get_node(f"ns={idx};s=Loom")  # the documented id, no trailing dot
            assert (await node.read_browse_name()).Name == "Loom"
            history = await var(viewer, "Admin/ProgramHistory")
            assert await history.read_attribute(ua.AttributeIds.ValueRank) is not None
            rank = (await history.read_attribute(ua.AttributeIds.ValueRank)).Value.Value
            assert rank == 1
            write = ua.AccessLevel.CurrentWrite.mask
            for who, writes in ((viewer, False), (operator, True)):
                cmd = await var(who, "Command/CntrlCmd")
                level = (await cmd.read_attribute(ua.AttributeIds.UserAccessLevel)).Value.Value
                assert bool(level & write) is writes
            mode = await var(operator, "Command/UnitMode")  # an admin's
            level = (await mode.read_attribute(ua.AttributeIds.UserAccessLevel)).Value.Value
            assert not level & write
            assert await read(viewer, "Status/StateRequested") == State.STOPPED
            assert await read(viewer, "Status/StateChangeInProcess") is False
            assert await read(viewer, "Status/UnitModeRequested") == UnitMode.PRODUCTION

    run(scenario())


@pytest.mark.slow
def test_a_program_is_loaded_over_opc_ua_with_the_refusals_of_rest(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path) as r, r.session("operator") as client:
            root = await loom(client)
            idx = await client.get_namespace_index(NAMESPACE)
            pid = await root.call_method(f"{idx}:LoadProgram", "braid.bws", TEXT)
            assert pid == r.controller.program_id == 1
            assert r.journal.program(pid).name == "braid.bws"
            with pytest.raises(UaStatusCodeError):
                await root.call_method(
                    f"{idx}:LoadProgram", "bad.bws", "FILL row=0 col=0\nX\nEND\nROW 9:+1\n"
                )
            reason = await read(client, "Status/CmdInvalidReason")
            assert "bad.bws:4:" in reason  # the line (and column) of the fault
            assert r.controller.program_id == pid
        async with rig(mock, tmp_path / "again") as r, r.session("viewer") as client:
            root = await loom(client)
            with pytest.raises(UaStatusCodeError) as viewer:
                await root.call_method(f"{idx}:LoadProgram", "braid.bws", TEXT)
            assert viewer.value.code == ua.StatusCodes.BadUserAccessDenied
            assert r.controller.program is None

    run(scenario())


@pytest.mark.slow
def test_the_server_certificate_names_the_machine_and_the_address_it_listens_on(mock, tmp_path):
    """A client that checks the host name finds it: the machine's name, localhost and the
    listening address (here loopback) are in the certificate's subject alternative names."""

    async def scenario() -> None:
        async with rig(mock, tmp_path) as r:
            der = (r.folder / CERT_FILE).read_bytes()
            names = (
                x509.load_der_x509_certificate(der)
                .extensions.get_extension_for_class(x509.SubjectAlternativeName)
                .value
            )
            assert socket.gethostname() in names.get_values_for_type(x509.DNSName)
            assert "localhost" in names.get_values_for_type(x509.DNSName)
            assert ipaddress.ip_address("127.0.0.1") in names.get_values_for_type(x509.IPAddress)

    run(scenario())


@pytest.mark.slow
def test_a_read_of_every_tag_takes_one_status_snapshot(mock, tmp_path):
    """A PLC's Read of all the tags is answered from one status of the controller, not one
    per variable (each would rebuild the whole status)."""

    async def scenario() -> None:
        async with rig(mock, tmp_path) as r, r.session("viewer") as client:
            nodes = [await var(client, tag.path) for tag in TAGS]
            ctl = r.controller
            calls: list[float] = []
            status = ctl.status

            def counted() -> Any:
                if sys._getframe(1).f_code.co_name == "_status_values":  # a Read, not the tick
                    calls.append(time.monotonic())
                return status()

            ctl.status = counted  # type: ignore[method-assign]  # counts the door's reads
            values = await client.read_values(nodes)
            assert len(values) == len(TAGS) and values[0] == State.STOPPED
            assert len(calls) == 1
            await client.read_values(nodes)
            assert len(calls) == 2  # a new Read, a new snapshot: never a stale one

    run(scenario())


def test_the_state_requested_is_where_an_acting_state_ends():
    assert requested(State.RESETTING) is State.IDLE
    assert requested(State.HOLDING) is State.HELD
    assert requested(State.STARTING) is State.EXECUTE
    assert requested(State.ABORTING) is State.ABORTED
    assert requested(State.EXECUTE) is State.EXECUTE  # not acting: where it is
    assert requested(State.STOPPED) is State.STOPPED
