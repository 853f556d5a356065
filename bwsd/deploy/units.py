"""The systemd units of an installation: the shipped ones (systemd/), filled in.

The shipped units are complete for the documented layout: bwsd in the venv ``/opt/bwsd``,
its config ``/etc/bwsd/bwsd.toml``, its state in ``/var/lib/bwsd`` (systemd's
``StateDirectory=``), a dynamic user. ``render`` fills them in for another layout: the
scripts of the installation that runs it, another config, a state folder of its own (a loom
folder of `bwsd init`, made writable with ``ReadWritePaths=``) and a named user.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

from bwsd.errors import BwsdError
from bwsd.shipped import unit_file

UNITS = ("bwsd.service", "bwsd-simulator.service")
SHIPPED_BIN = "/opt/bwsd/bin/"
SHIPPED_CONFIG = "/etc/bwsd/bwsd.toml"
SHIPPED_PROGRAM = "example:braid-2x2.bws"
SYSTEM_STATE = Path("/var/lib/bwsd")  # StateDirectory=bwsd
HOMES = (Path("/home"), Path("/root"), Path("/run/user"))  # what ProtectHome=yes hides
TEMPS = (Path("/tmp"), Path("/var/tmp"))  # what PrivateTmp=yes replaces


@dataclass(frozen=True)
class Layout:
    """Where an installation's parts are, as the service sees them."""

    bin_dir: Path  # the folder of the bwsd script (a venv's bin/)
    config: Path
    program: str = SHIPPED_PROGRAM  # the mock loom's, whose FILL places its cases
    state_dir: Path | None = None  # None: systemd's StateDirectory=bwsd (/var/lib/bwsd)
    user: str | None = None  # None: a dynamic user


def this_installation() -> Path:
    """The folder of the bwsd script beside the running Python (a venv's or pipx's bin/)."""
    bin_dir = Path(sys.executable).parent
    if not (bin_dir / "bwsd").is_file():
        raise BwsdError(
            f"no bwsd script beside this Python ({sys.executable}): run the bwsd of the "
            "installation the service is to run (for example /opt/bwsd/bin/bwsd)"
        )
    return bin_dir


def in_home(path: Path) -> bool:
    """Whether ``path`` lies where ProtectHome=yes hides it."""
    return any(path.is_relative_to(home) for home in HOMES)


def _in_temp(path: Path) -> bool:
    return any(path.is_relative_to(temp) for temp in TEMPS)


def _replace(text: str, old: str, new: str) -> str:
    if old not in text:
        raise BwsdError(f"the shipped unit has no {old!r} to fill in: the installation is damaged")
    return text.replace(old, new)


def _state_lines(text: str, state_dir: Path) -> str:
    """A state folder of its own in place of systemd's StateDirectory=."""
    text = text.replace("StateDirectoryMode=0700\n", "")
    text = _replace(text, "StateDirectory=bwsd\n", f"ReadWritePaths={state_dir}\n")
    return _replace(text, "WorkingDirectory=%S/bwsd\n", f"WorkingDirectory={state_dir}\n")


def _body(name: str, made_by: str) -> str:
    """The shipped unit without its opening comment (which speaks of the shipped layout)."""
    lines = unit_file(name).splitlines(keepends=True)
    start = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    return f"# {name}, written by {made_by} (docs/service.md).\n" + "".join(lines[start:])


def render(name: str, layout: Layout, made_by: str) -> str:
    """The shipped unit ``name`` filled in for ``layout``, saying it was written by ``made_by``."""
    text = _replace(_body(name, made_by), SHIPPED_BIN, f"{layout.bin_dir}/")
    text = _replace(text, SHIPPED_CONFIG, str(layout.config))
    if name == "bwsd-simulator.service":
        text = _replace(text, SHIPPED_PROGRAM, layout.program)
    elif layout.state_dir is not None:
        text = _state_lines(text, layout.state_dir)
    if layout.state_dir is not None:  # a loom folder: its config is not in /etc/bwsd
        text = _replace(text, "ConfigurationDirectory=bwsd\n", "")
    if layout.user is not None:
        text = _replace(text, "DynamicUser=yes\n", f"User={layout.user}\n")
    where = [layout.bin_dir, layout.config, *([layout.state_dir] if layout.state_dir else [])]
    if any(in_home(path) for path in where):  # readable there, writable where it must be
        text = _replace(text, "ProtectHome=yes\n", "ProtectHome=read-only\n")
    if any(_in_temp(path) for path in where):  # a private /tmp would hide them
        text = _replace(text, "PrivateTmp=yes\n", "PrivateTmp=no\n")
    return text
