"""`bwsd init DIR`: a loom's folder, everything a plant needs to run one loom from it.

    DIR/loom.toml            the config, every key set and commented ([daemon] state_dir =
                             "state": the state folder is DIR/state, wherever a command runs)
    DIR/state/               the daemon's state folder (journal, tokens), mode 0700
    DIR/examples/            the shipped example programs, their configs and the sweep spec
    DIR/systemd/             bwsd.service and bwsd-simulator.service for this folder and
                             this installation, to copy to /etc/systemd/system

The folder is made whole or not at all: it is built beside DIR under a temporary name and
renamed into place. DIR may exist only as an empty folder.
"""

from __future__ import annotations

import os
import pwd
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

from bwsd.deploy.units import UNITS, Layout, render, this_installation
from bwsd.errors import BwsdError
from bwsd.shipped import DEMO_CONFIG, DEMO_PROGRAM, config_file, examples

CONFIG_NAME = "loom.toml"


@dataclass(frozen=True)
class Made:
    """What `bwsd init` made: the folder, its config, its units."""

    folder: Path
    config: Path
    units: tuple[Path, ...]


def current_user() -> str:
    """The name of the user running this command."""
    return pwd.getpwuid(os.geteuid()).pw_name


def _check_target(folder: Path) -> None:
    if folder.is_symlink() or (folder.exists() and not folder.is_dir()):
        raise BwsdError(f"{folder}: exists and is not a folder: nothing written")
    if folder.is_dir() and any(folder.iterdir()):
        raise BwsdError(
            f"{folder}: is not empty; `bwsd init` makes a new loom folder: nothing written"
        )
    if not folder.parent.is_dir():
        raise BwsdError(f"{folder.parent}: no such folder: nothing written")


def _fill(work: Path, folder: Path, user: str) -> None:
    """Write the loom folder's files into ``work``, naming ``folder`` (its final place)."""
    shutil.copyfile(config_file(DEMO_CONFIG), work / CONFIG_NAME)
    (work / "state").mkdir(mode=0o700)
    (work / "examples").mkdir()
    for example in examples():
        if example.name != DEMO_CONFIG:
            shutil.copyfile(example.path, work / "examples" / example.name)
    layout = Layout(
        bin_dir=this_installation(),
        config=folder / CONFIG_NAME,
        program=str(folder / "examples" / DEMO_PROGRAM),
        state_dir=folder / "state",
        user=user,
    )
    (work / "systemd").mkdir()
    for name in UNITS:
        text = render(name, layout, f"`bwsd init {folder}`")
        (work / "systemd" / name).write_text(text, encoding="utf-8")


def init_folder(folder: Path, user: str | None = None) -> Made:
    """Make the loom folder ``folder`` (absolute in its units); its units run as ``user``
    (default: the user running this)."""
    folder = folder.absolute()
    _check_target(folder)
    work = Path(tempfile.mkdtemp(prefix=f".{folder.name}.init-", dir=folder.parent))
    try:
        work.chmod(0o755)
        _fill(work, folder, user or current_user())
        if folder.is_dir():
            folder.rmdir()  # empty, checked above
        work.rename(folder)
    except BaseException:
        shutil.rmtree(work, ignore_errors=True)
        raise
    units = tuple(folder / "systemd" / name for name in UNITS)
    return Made(folder, folder / CONFIG_NAME, units)
