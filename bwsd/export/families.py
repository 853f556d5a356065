"""Yarn families (``YarnData.family``) and their stable integer codes."""

from __future__ import annotations

from bwsd.twin.skeleton import SkeletonData


def family_codes(sk: SkeletonData) -> dict[str, int]:
    """Code per family: 0 for ``warp``, then 1, 2, ... for weft families in yarn-id order."""
    codes = {"warp": 0}
    for yarn in sorted(sk.yarns, key=lambda y: y.id):
        codes.setdefault(yarn.family, len(codes))
    return codes
