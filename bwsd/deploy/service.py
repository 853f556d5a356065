"""`bwsd service install`: the systemd units of this installation, and its config.

Writes ``/etc/systemd/system/bwsd.service`` and ``bwsd-simulator.service`` for the venv (or
pipx install) it runs from, and ``/etc/bwsd/bwsd.toml`` when there is none: the shipped
loom config with ``[daemon] state_dir = "/var/lib/bwsd"``, the folder systemd makes for the
service (``StateDirectory=bwsd``), so that `bwsd token` and `bwsd journal`, run by an
administrator with the same config, find the daemon's folder. A config already there is kept;
it is checked first, and one whose state folder is another is refused. ``--prefix DIR``
writes under DIR instead of ``/`` (an image being built, or a look before installing); the
units still name ``/etc/bwsd`` and ``/var/lib/bwsd``. Everything is checked before the first
file is written.
"""

from __future__ import annotations

import os
import pwd
from dataclasses import dataclass
from pathlib import Path

from bwsd.config import load_config
from bwsd.deploy.units import (
    SHIPPED_CONFIG,
    SYSTEM_STATE,
    UNITS,
    Layout,
    in_home,
    render,
    this_installation,
)
from bwsd.errors import BwsdError
from bwsd.paths import configured_state_folder
from bwsd.shipped import DEMO_CONFIG, config_file

UNIT_FOLDER = Path("/etc/systemd/system")
STATE_LINE = 'state_dir = "state"'  # in the shipped loom config


@dataclass(frozen=True)
class Written:
    """A file of the install: where it went, and whether it was written or kept."""

    path: Path
    kept: bool = False


def _under(root: Path, path: Path) -> Path:
    return root / path.relative_to("/")


def _check_user(user: str | None, root: Path) -> None:
    if user is None or root != Path("/"):
        return  # a dynamic user; or an image, whose users are not this machine's
    try:
        pwd.getpwnam(user)
    except KeyError:
        raise BwsdError(f"--user {user}: no such user on this machine: nothing written") from None


def _check_installation(bin_dir: Path) -> None:
    if in_home(bin_dir):
        raise BwsdError(
            f"this installation lies in {bin_dir.parent}, which the service's ProtectHome=yes "
            "hides from it: install bwsd into a venv under /opt (python3 -m venv /opt/bwsd; "
            "/opt/bwsd/bin/pip install bwsd), or with pipx under PIPX_HOME=/opt/pipx; nothing "
            "written"
        )


def _config_text(target: Path) -> str | None:
    """The config to write at ``target`` (None: keep the one there, checked)."""
    if target.exists():
        config = load_config(target)
        state = configured_state_folder(config)
        if state != SYSTEM_STATE:
            raise BwsdError(
                f"{target}: [daemon] state_dir is {config.table('daemon')['state_dir']!r}, but "
                f'the service keeps its state in {SYSTEM_STATE}: set state_dir = "{SYSTEM_STATE}"'
                "; nothing written"
            )
        return None
    text = config_file(DEMO_CONFIG).read_text(encoding="utf-8")
    if STATE_LINE not in text:
        raise BwsdError(f"the shipped {DEMO_CONFIG} has no {STATE_LINE!r} line to set")
    return text.replace(STATE_LINE, f'state_dir = "{SYSTEM_STATE}"', 1)


def _write(path: Path, text: str, mode: int) -> None:
    """Write ``path`` whole (a temporary file renamed into place)."""
    path.parent.mkdir(mode=0o755, parents=True, exist_ok=True)
    part = path.with_name(f".{path.name}.part")
    part.write_text(text, encoding="utf-8")
    part.chmod(mode)
    os.replace(part, path)


def install(user: str | None = None, prefix: Path | None = None) -> list[Written]:
    """Write the units (and the config when missing) under ``prefix`` (default ``/``)."""
    root = (prefix or Path("/")).absolute()
    bin_dir = this_installation()
    _check_installation(bin_dir)
    _check_user(user, root)
    config = _under(root, Path(SHIPPED_CONFIG))
    config_text = _config_text(config)
    layout = Layout(bin_dir=bin_dir, config=Path(SHIPPED_CONFIG), user=user)
    units = {name: render(name, layout, "`bwsd service install`") for name in UNITS}
    done = []
    if config_text is None:
        done.append(Written(config, kept=True))
    else:
        _write(config, config_text, 0o644)
        done.append(Written(config))
    for name, text in units.items():
        path = _under(root, UNIT_FOLDER / name)
        _write(path, text, 0o644)
        done.append(Written(path))
    return done
