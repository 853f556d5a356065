"""The machine configs, example programs and systemd units shipped with the package.

They are ``config/``, ``examples/`` and ``systemd/`` of the source tree, which
``bwsd/shipped/config``, ``bwsd/shipped/examples`` and ``bwsd/shipped/systemd`` link to; a
wheel carries them here as package data. Found through ``importlib.resources``, so they are
reached from any folder, installed or editable.

Every command that takes a program or a config file takes ``example:NAME`` for a shipped
one (``example:braid-L.bws``, ``example:braid-L.toml``); ``bwsd examples`` lists them.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path

from bwsd.errors import BwsdError

__all__ = [
    "DEMO_CONFIG",
    "DEMO_PROGRAM",
    "EXAMPLE",
    "Example",
    "config_file",
    "example_file",
    "examples",
    "is_shipped",
    "resolve",
    "unit_file",
]

DEMO_CONFIG = "loom.toml"  # the 8-carrier braiding machine and its mock loom
DEMO_PROGRAM = "braid-2x2.bws"  # the 8-carrier 4-step braid
EXAMPLE = "example:"  # a file named example:NAME is the shipped NAME
FOLDERS = ("examples", "config")  # where example:NAME is looked for, in this order
SUFFIXES = {".bws": "program", ".sweep.toml": "sweep spec", ".toml": "machine config"}


def _folder(folder: str) -> Path:
    resource = files(__name__) / folder
    # Installed packages are plain files (pip unpacks wheels): the path can be handed on.
    if not isinstance(resource, Path):
        raise BwsdError(f"{folder}/ of this installation of bwsd is not a folder on disk")
    return resource


def _shipped(folder: str, name: str) -> Path:
    path = _folder(folder) / name
    if "/" in name or not path.is_file():
        raise BwsdError(f"{folder}/{name} is not shipped with this installation of bwsd")
    return path


def config_file(name: str = DEMO_CONFIG) -> Path:
    """A shipped machine config: ``config_file("braid-24x24.toml")``."""
    return _shipped("config", name)


def example_file(name: str = DEMO_PROGRAM) -> Path:
    """A shipped example program (or sweep spec): ``example_file("weave-U.bws")``."""
    return _shipped("examples", name)


def unit_file(name: str) -> str:
    """The text of a shipped systemd unit: ``unit_file("bwsd.service")``."""
    return _shipped("systemd", name).read_text(encoding="utf-8")


@dataclass(frozen=True)
class Example:
    """A shipped file: its name (as in ``example:NAME``), what it is, its first comment."""

    name: str
    kind: str
    path: Path
    title: str


def _kind(name: str) -> str:
    return next(kind for suffix, kind in SUFFIXES.items() if name.endswith(suffix))


def _title(path: Path) -> str:
    first = path.read_text(encoding="utf-8").split("\n", 1)[0]
    return first.removeprefix("#").strip() if first.startswith("#") else ""


def examples() -> list[Example]:
    """Every shipped program, sweep spec and machine config, programs first, by name."""
    found = []
    for folder in FOLDERS:
        for path in sorted(_folder(folder).iterdir()):
            if path.is_file() and path.name.endswith(tuple(SUFFIXES)):
                found.append(Example(path.name, _kind(path.name), path, _title(path)))
    return found


def resolve(given: str | Path) -> Path:
    """A file named on the command line: ``example:NAME`` is the shipped NAME (a program or
    sweep spec of ``examples/``, else a config of ``config/``), anything else a path."""
    text = str(given)
    if not text.startswith(EXAMPLE):
        return Path(given)
    name = text.removeprefix(EXAMPLE)
    for folder in FOLDERS:
        path = _folder(folder) / name
        if name and "/" not in name and path.is_file():
            return path
    known = ", ".join(example.name for example in examples())
    raise BwsdError(f"{text}: no such example (shipped: {known}; `bwsd examples` lists them)")


def is_shipped(path: str | Path) -> bool:
    """Whether ``path`` names a file inside the package's shipped folders, as
    ``resolve("example:NAME")`` gives it (not the source tree's ``config/`` they link to)."""
    where = Path(path).absolute()
    return any(where.is_relative_to(_folder(folder).absolute()) for folder in FOLDERS)
