"""`bwsd program KIND [options]`: print a generated program, optionally write its config."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from bwsd.errors import BwsdError
from bwsd.program.render import Generated
from bwsd.program.sections import SHAPES as BRAID_SHAPES
from bwsd.program.sections import WEAVE_SHAPES
from bwsd.program.sections import WEFT_ANGLES as ANGLES
from bwsd.twin.exact import decimal_float


class GeneratorError(BwsdError):
    """The requested program cannot be generated (bad combination of options)."""


def _block(text: str) -> tuple[int, int]:
    """A block size written ROWSxCOLS, e.g. 2x6."""
    rows, sep, cols = text.lower().partition("x")
    if not sep or not rows.isdigit() or not cols.isdigit():
        raise argparse.ArgumentTypeError(f"expected ROWSxCOLS, got {text!r}")
    return int(rows), int(cols)


def _angles(text: str) -> tuple[float, ...]:
    """Weft angles in degrees written 0,90,45,-45 (any angle: 30,-30,22.5)."""
    try:
        angles = tuple(decimal_float(part.strip()) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected angles in degrees like 0,90,45,-45, got {text!r}"
        ) from None
    return angles


def _section(p: argparse.ArgumentParser, side: int, takeup: float) -> None:
    """The braided section's options (a rect of ``side`` x ``side`` by default)."""
    p.add_argument("--rows", type=int, default=side, help=f"body rows of a rect section ({side})")
    p.add_argument(
        "--cols", type=int, default=side, help=f"body columns of a rect section ({side})"
    )
    p.add_argument("--shape", choices=BRAID_SHAPES, default="rect")
    p.add_argument("--flange", type=_block, default=(2, 6), help="L/T/I flange, ROWSxCOLS")
    p.add_argument("--web", type=_block, default=(4, 2), help="L/T/I web, ROWSxCOLS")
    p.add_argument(
        "--segments",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="L/T/I: the machine has the corner line segments (the default; "
        "--no-segments: whole-line shifts only, L and T)",
    )
    p.add_argument(
        "--takeup", type=float, default=takeup, help=f"take-up per four steps, mm ({takeup:g})"
    )


def _braided(args: argparse.Namespace) -> dict[str, Any]:
    """The section and take-up arguments of braid4 and braid-weave."""
    names = ("shape", "flange", "web", "segments", "takeup")
    return {n: getattr(args, n) for n in names}


def _common(parser: argparse.ArgumentParser, cycles: bool = True) -> None:
    if cycles:
        parser.add_argument("--cycles", type=int, default=10, help="machine cycles (10)")
    parser.add_argument("--pitch", type=float, help="guide pitch along x and y, mm")
    parser.add_argument("--d-mat", type=float, help="matrix to fell distance, mm")
    parser.add_argument("--c-mat", type=float, help="convergence ratio, 0..1")
    parser.add_argument("--diameter", type=float, help="yarn diameter, mm")
    parser.add_argument(
        "--config-out", metavar="FILE", help="also write the matching machine config (TOML) to FILE"
    )


def _kinds(sub: Any) -> None:
    p = sub.add_parser("twist", help="two yarns twisted in a 2 x 2 matrix")
    p.add_argument("--turns", type=int, default=4, help="full turns (4)")
    p.add_argument(
        "--takeup",
        type=float,
        default=0.0,
        help="take-up after each turn, mm (0: none, the worked example)",
    )
    _common(p, cycles=False)
    p = sub.add_parser("braid4", help="4-step braid of a rectangular, L, T or I section")
    _section(p, 2, 6.0)
    _common(p)
    p = sub.add_parser("braid-weave", help="4-step braid with a layer of wefts every N cycles")
    _section(p, 3, 3.0)
    p.add_argument("--weft-every", type=int, default=2, help="cycles between weft layers (2)")
    p.add_argument(
        "--angles",
        type=_angles,
        default=ANGLES,
        help="weft angles in degrees, any, taken in turn, layer by layer (0,90,45,-45)",
    )
    _common(p)
    p.set_defaults(cycles=8)
    p = sub.add_parser("weave-plain", help="plain weave of one warp layer")
    p.add_argument("--warps", type=int, default=10, help="warps in the layer (10)")
    p.add_argument("--takeup", type=float, default=4.0, help="take-up per pick, mm (4)")
    _common(p)
    p = sub.add_parser("weave-3d", help="dual-direction 3D weave of a warp grid or U")
    p.add_argument("--layers", type=int, default=3, help="warp layers (3)")
    p.add_argument("--warps", type=int, default=5, help="warps per layer (5)")
    p.add_argument("--shape", choices=WEAVE_SHAPES, default="rect")
    p.add_argument("--leg", type=int, default=2, help="U leg thickness, warps (2)")
    p.add_argument("--base", type=int, default=2, help="U base thickness, layers (2)")
    p.add_argument("--takeup", type=float, default=5.0, help="take-up per pick, mm (5)")
    _common(p)


def configure(sub: Any) -> None:
    """Register `bwsd program` on the top-level subcommand action."""
    parser = sub.add_parser(
        "program",
        help="print a generated .bws program",
        description="Print a generated .bws program (twist, braids, weaves) on stdout.",
    )
    kinds = parser.add_subparsers(dest="kind", required=True, metavar="KIND")
    _kinds(kinds)
    parser.set_defaults(handler=run)


def _machine_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    names = ("pitch", "d_mat", "c_mat", "diameter")
    return {n: getattr(args, n) for n in names if getattr(args, n) is not None}


def generate(args: argparse.Namespace) -> Generated:
    """Call the generator the parsed arguments name (imported here: the weaves need the twin)."""
    from bwsd.program.braid import braid4, twist

    machine = _machine_kwargs(args)
    if args.kind == "twist":
        return twist(args.turns, takeup=args.takeup, **machine)
    if args.kind == "braid4":
        return braid4(args.rows, args.cols, args.cycles, **_braided(args), **machine)
    if args.kind == "braid-weave":
        from bwsd.program.braidweave import braid_weave

        return braid_weave(
            args.rows,
            args.cols,
            args.cycles,
            weft_every=args.weft_every,
            angles=args.angles,
            **_braided(args),
            **machine,
        )
    from bwsd.program.weave import weave_3d, weave_plain

    if args.kind == "weave-plain":
        return weave_plain(args.warps, args.cycles, takeup=args.takeup, **machine)
    return weave_3d(
        args.layers,
        args.warps,
        args.cycles,
        shape=args.shape,
        leg=args.leg,
        base=args.base,
        takeup=args.takeup,
        **machine,
    )


def run(args: argparse.Namespace) -> int:
    """Print the program; write the config when asked. Nothing is written on a bad request."""
    try:
        generated = generate(args)
    except ValueError as exc:
        raise GeneratorError(f"program {args.kind}: {exc}") from exc
    if args.config_out:
        try:
            Path(args.config_out).write_text(generated.config_toml(), encoding="utf-8")
        except OSError as exc:
            raise GeneratorError(f"cannot write {args.config_out}: {exc.strerror}") from exc
    sys.stdout.write(generated.program)
    return 0
