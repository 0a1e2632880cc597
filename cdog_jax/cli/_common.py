"""Argument types, checks and output that the commands share."""

from __future__ import annotations

import argparse
import math
import sys

from .._method import method_names
from ..io._errors import InputError


def int_at_least(low: int, why: str = ""):
    """An argparse ``type``: an integer ``>= low`` (``why`` is added to the refusal)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer >= {low}; got {text!r}") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"must be an integer >= {low}{why}; got {text}")
        return value

    return parse


def seed_int(text: str) -> int:
    """An argparse ``type``: a PRNG seed, an integer that fits in 64 bits (what JAX's keys
    take)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer; got {text!r}") from None
    if not -(2**63) <= value < 2**63:
        raise argparse.ArgumentTypeError(
            f"must be an integer in [-2**63, 2**63) (a 64-bit seed); got {text}"
        )
    return value


_positive_int = int_at_least(1)
_nonnegative_int = int_at_least(0)


def _nonnegative_float(text: str) -> float:
    """A finite number >= 0 (a σ in pixels, …)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number >= 0; got {text!r}") from None
    if not (value >= 0.0 and math.isfinite(value)):  # also rejects NaN
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0; got {text}")
    return value


def check_sigma_fits(sigma: float, diagonal: float, where: str) -> None:
    """Refuse a noise σ (px) larger than the image diagonal (px): no detection noise is
    that large, and the thresholds it sets would accept every pairing."""
    if sigma > diagonal:
        raise InputError(
            f"{where}: --sigma {sigma:g} px is larger than the image diagonal ({diagonal:.0f} px)"
        )


_FIGURE_EXTENSIONS = (".png", ".pdf", ".svg", ".jpg", ".jpeg")


def _emit(lines: list[str]) -> None:
    """Print ``lines``; characters the terminal cannot encode (σ, τ, █) are replaced."""
    text = "\n".join(lines) + "\n"
    try:
        sys.stdout.write(text)
    except UnicodeEncodeError:
        encoding = getattr(sys.stdout, "encoding", None) or "ascii"
        sys.stdout.write(text.encode(encoding, "replace").decode(encoding))
    sys.stdout.flush()


def _method_name(text: str) -> str:
    """A registered method's name (checked when the arguments are parsed)."""
    if text not in method_names():
        raise argparse.ArgumentTypeError(
            f"unknown method {text!r}; registered: {', '.join(method_names())}"
        )
    return text


def add_method_argument(parser: argparse.ArgumentParser) -> None:
    """``--method NAME``: a registered method, default best."""
    parser.add_argument(
        "--method",
        dest="method",
        type=_method_name,
        default="best",
        metavar="NAME",
        help="a registered method: best (default, the most accurate), extended (ours beyond the paper), paper (the "
        "paper's C-DOG), reference (the original code's), or any other registered one",
    )
