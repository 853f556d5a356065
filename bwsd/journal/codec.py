"""Payloads as JSON text: a dict with string keys, finite numbers, nothing else."""

from __future__ import annotations

import json
from typing import Any


def dump(payload: dict[str, Any]) -> str:
    """Compact JSON of ``payload``; ValueError naming what cannot be stored."""
    if not isinstance(payload, dict):
        raise ValueError(f"payload must be a dict, got {type(payload).__name__}")
    if bad := [key for key in payload if not isinstance(key, str)]:
        raise ValueError(f"payload keys must be strings, got {bad[0]!r}")
    try:
        return json.dumps(payload, separators=(",", ":"), allow_nan=False, ensure_ascii=False)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"payload is not JSON: {exc}") from exc


def load(text: str) -> dict[str, Any]:
    """The dict stored by ``dump``."""
    value = json.loads(text)
    if not isinstance(value, dict):
        raise ValueError(f"stored payload is not a JSON object: {text[:40]!r}")
    return value


def load_optional(text: str | None) -> dict[str, Any] | None:
    """``load`` for a payload that may be absent."""
    return None if text is None else load(text)
