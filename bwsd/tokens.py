"""Bearer tokens with roles (viewer < operator < admin); the token file keeps only hashes.

The file (``[api] tokens_file``) is JSON::

    {"version": 1, "tokens": [{"name": "line-3", "role": "operator",
                               "sha256": "<hex digest of the token>", "created": 1718000000.0}]}

A token is shown once, when it is created; afterwards only its sha256 exists. The store
reloads the file when it changes on disk, so a token added or removed with ``bwsd token``
takes effect without a restart: every door checks the token again at each command.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import re
import secrets
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Literal, get_args

from bwsd.errors import BwsdError
from bwsd.paths import write_private

Role = Literal["viewer", "operator", "admin"]
ROLES: tuple[Role, ...] = get_args(Role)
RANK: dict[str, int] = {role: rank for rank, role in enumerate(ROLES)}
FILE_VERSION = 1
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")
_HEX = re.compile(r"[0-9a-f]{64}")


class TokenError(BwsdError):
    """The token file cannot be read or written, or a token request is malformed."""


@dataclass(frozen=True)
class TokenEntry:
    """One token as stored: who holds it, its role, the sha256 of the token, when made."""

    name: str
    role: Role
    sha256: str
    created: float


def digest(token: str) -> str:
    """The sha256 of a token, as hex: what the file stores."""
    return hashlib.sha256(token.encode("utf-8", "surrogatepass")).hexdigest()


def check_role(role: str) -> Role:
    """``role`` if it is one of ROLES; TokenError otherwise."""
    for known in ROLES:
        if role == known:
            return known
    raise TokenError(f"unknown role {role!r} (one of {', '.join(ROLES)})")


class TokenStore:
    """The hashed tokens of one file; ``check`` answers who holds a token."""

    def __init__(self, path: Path, entries: list[TokenEntry]) -> None:
        """Use ``load``."""
        self.path = path
        self._entries = entries
        self._stamp = _stamp(path)

    @classmethod
    def load(cls, path: str | Path) -> TokenStore:
        """Read the token file; a file that does not exist yet is an empty store."""
        where = Path(path)
        return cls(where, _read(where))

    @property
    def entries(self) -> tuple[TokenEntry, ...]:
        """The stored tokens (hashes only), in file order."""
        self._refresh()
        return tuple(self._entries)

    def add(self, name: str, role: str) -> str:
        """Create a token for ``name`` with ``role``; the clear token, returned this once."""
        if not _NAME.fullmatch(name):
            raise TokenError(
                f"token name {name!r}: 1 to 64 letters, digits, '.', '_' or '-', "
                "starting with a letter or digit"
            )
        checked = check_role(role)
        self._refresh()
        if any(entry.name == name for entry in self._entries):
            raise TokenError(f"a token named {name!r} exists already (remove it first)")
        token = secrets.token_urlsafe(32)
        entry = TokenEntry(name, checked, digest(token), time.time())
        self._save([*self._entries, entry])
        return token

    def remove(self, name: str) -> None:
        """Revoke the token called ``name``."""
        self._refresh()
        kept = [entry for entry in self._entries if entry.name != name]
        if len(kept) == len(self._entries):
            raise TokenError(f"no token named {name!r}")
        self._save(kept)

    def check(self, token: str) -> tuple[str, Role] | None:
        """(name, role) of the holder of ``token``, or None; compares every entry in full."""
        self._refresh()
        wanted = digest(token)
        found: TokenEntry | None = None
        for entry in self._entries:
            if hmac.compare_digest(wanted, entry.sha256):
                found = entry
        return None if found is None else (found.name, found.role)

    def _refresh(self) -> None:
        """Reload the file if it changed; a file broken meanwhile keeps the tokens known."""
        stamp = _stamp(self.path)
        if stamp == self._stamp:
            return
        try:
            self._entries = _read(self.path)
        except TokenError:
            return
        self._stamp = stamp

    def _save(self, entries: list[TokenEntry]) -> None:
        document = {"version": FILE_VERSION, "tokens": [asdict(e) for e in entries]}
        _write_atomic(self.path, json.dumps(document, indent=1) + "\n")
        self._entries = entries
        self._stamp = _stamp(self.path)


def _stamp(path: Path) -> tuple[int, int, int] | None:
    try:
        st = path.stat()
    except OSError:
        return None
    return (st.st_ino, st.st_mtime_ns, st.st_size)


def _read(path: Path) -> list[TokenEntry]:
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        return []
    except (OSError, UnicodeDecodeError) as exc:
        raise TokenError(f"{path}: cannot read: {exc}") from exc
    try:
        data = json.loads(text)
        if data.get("version") != FILE_VERSION:
            raise ValueError(f"version must be {FILE_VERSION}")
        return [_entry(item) for item in data["tokens"]]
    except (AttributeError, KeyError, TypeError, ValueError) as exc:
        raise TokenError(f"{path}: not a token file: {exc}") from exc


def _entry(item: Any) -> TokenEntry:
    name, sha, created = item["name"], item["sha256"], item["created"]
    if not isinstance(name, str) or not isinstance(sha, str) or not _HEX.fullmatch(sha):
        raise ValueError(f"malformed entry {item!r}")
    if isinstance(created, bool) or not isinstance(created, int | float):
        raise ValueError(f"malformed entry {item!r}")
    try:
        role = check_role(item["role"])
    except TokenError as exc:
        raise ValueError(str(exc)) from None
    return TokenEntry(name, role, sha, float(created))


def _write_atomic(path: Path, text: str) -> None:
    """Write the token file in one step (``write_private``); TokenError if it cannot."""
    try:
        write_private(path, text.encode("utf-8"))
    except OSError as exc:
        raise TokenError(f"{path}: cannot write: {exc.strerror}") from exc
