"""PackML over OPC UA (asyncua), secured (docs/opcua.md). Needs the ``opcua`` extra."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from bwsd.config import Config
from bwsd.extras import OPCUA, needs

if TYPE_CHECKING:
    from bwsd.controller.facade import Controller
    from bwsd.gate import Gate
    from bwsd.opcua.server import OpcUaServer


def opcua_server(
    controller: Controller, config: Config, state_dir: Path, gate: Gate | None = None
) -> OpcUaServer | None:
    """The server of the config's ``[opcua]`` table, or None when it is not enabled; its
    users are the tokens of ``gate`` (else of the state folder's token file)."""
    table = config.table("opcua")
    if not table["enabled"]:
        return None
    with needs(OPCUA, "[opcua] enabled = true"):
        from bwsd.opcua.server import OpcUaServer
        from bwsd.tokens import TokenStore
    from bwsd.paths import opcua_folder, tokens_file

    tokens = gate.tokens if gate is not None else None
    if tokens is None:
        tokens = TokenStore.load(tokens_file(config, state_dir))
    return OpcUaServer(controller, tokens, opcua_folder(config, state_dir), table, gate)
