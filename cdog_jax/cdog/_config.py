"""The words C-DOG's stages declare their options in (docs/ARCHITECTURE.md, "How to add a
stage"), and the epipolar gate τ.

A stage's options are declared once, in the file of its rule: its structural options are the
fields (with defaults) of its options ``NamedTuple`` (static: part of the jit key), its
numbers are :class:`Threshold` entries (traced: a sweep over them compiles once), and the
switch that turns it on is a :class:`Switch`. ``cdog_jax/cdog/_pipeline.py`` writes each
declared option as a field of :class:`cdog_jax.Config` (hashable, a static argument of
``jax.jit``; checked against the declarations on import) and derives from them the traced
:class:`cdog_jax.Thresholds` and the ranges of the numbers.
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import jax.numpy as jnp
import numpy as np
from jax.scipy.special import erf

from .._types import Array, Float

Adjacency = Literal["mutual", "union"]
PruneScope = Literal["all", "conflicts", "none"]
IqrScore = Literal["exclude_own", "include_own"]
IqrQuartiles = Literal["zero_pad", "positive"]
SigmaMode = Literal["given", "auto", "robust"]
ThresholdUnit = Literal["px", "focal"]
TauMode = Literal["gaussian", "fitted"]

DEFAULT_MIN_PARALLAX_DEG = 1.0
"""The validity gate's default parallax bound (degrees; ``Config.min_parallax_deg``)."""


class Range(NamedTuple):
    """Allowed values of a number: finite, ``low <= v`` (``<`` if ``low_open``) and
    ``v <= high`` (``<`` if ``high_open``)."""

    low: float = 0.0
    high: float = float("inf")
    low_open: bool = False
    high_open: bool = False

    def ok(self, value) -> np.ndarray:
        """Elementwise: ``value`` (a number or an array) is allowed."""
        value = np.asarray(value, np.float64)
        above = value > self.low if self.low_open else value >= self.low
        below = value < self.high if self.high_open else value <= self.high
        return np.asarray(np.isfinite(value) & above & below)

    def describe(self) -> str:
        lo, hi = (
            "(" if self.low_open else "[",
            ")" if self.high_open or self.high == float("inf") else "]",
        )
        return f"finite and in {lo}{self.low:g}, {self.high:g}{hi}"


class Threshold(NamedTuple):
    """A traced option of a stage: its name (a field of ``Config`` and of ``Thresholds``),
    default, allowed range, a one-line description (with its unit) and, for a length,
    ``unit`` ``"px"`` (``"px2"``: squared): scaled with the focal length when
    ``threshold_unit="focal"``."""

    name: str
    default: float
    range: Range = Range()
    doc: str = ""
    unit: str = ""


class Switch(NamedTuple):
    """The ``bool`` option (a field of ``Config``) that turns a stage on; as a stage's
    ``when``, it reads that field."""

    name: str
    default: bool
    doc: str = ""

    def __call__(self, config) -> bool:
        return getattr(config, self.name)


class AtLeast(NamedTuple):
    """A structural ``int`` option's lower bound other than 1, as ``Annotated[int, AtLeast(2)]``."""

    low: int


class OptionGroup(NamedTuple):
    """Options read before any stage runs (by ``associate_traced`` itself), declared like a
    stage's: ``options`` a ``NamedTuple`` of structural fields with defaults, ``numbers`` a
    tuple of :class:`Threshold`."""

    name: str
    options: type | None
    thresholds: tuple[Threshold, ...] = ()


class ThresholdsBase(tuple):
    """The base of :class:`cdog_jax.Thresholds`: a ``NamedTuple`` of traced scalars that a
    stage reads by name (``thresholds.delta``). The stages name this base, not the concrete type,
    which ``_pipeline.py`` derives from their declarations."""

    __slots__ = ()


def check_number(value, name: str, where: str, allowed: Range) -> None:
    """Raise unless ``value`` is a real number in ``allowed``; names ``where.name``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(
        value, (int, float, np.integer, np.floating)
    ):
        raise TypeError(
            f"{where}.{name} must be a real number; got {type(value).__name__} {value!r}"
        )
    if not allowed.ok(value):
        raise ValueError(f"{where}.{name} must be {allowed.describe()}; got {value!r}")


def tau_px(
    thresholds, sigma_px: Float[Array, ""], fitted_px: Float[Array, ""] | None = None
) -> Float[Array, ""]:
    """Epipolar gate ``τ = max(alpha_tau · √2 · σ, tau_min)`` in pixels (docs/ALGORITHM.md §1–2);
    ``thresholds`` holds ``alpha_tau`` and ``tau_min_px``. With ``fitted_px`` (the fitted quantile of
    the true-pair distance, NaN when there is none) ``τ = max(fitted_px, tau_min)`` where it
    is finite."""
    gaussian = thresholds.alpha_tau * jnp.sqrt(2.0) * sigma_px
    if fitted_px is not None:
        gaussian = jnp.where(jnp.isfinite(fitted_px), fitted_px, gaussian)
    return jnp.maximum(gaussian, thresholds.tau_min_px)


# With threshold_unit="focal" the numbers of unit "px" ("px2") are pixels of a camera of focal
# length REFERENCE_FOCAL_PX: scaled by f / REFERENCE_FOCAL_PX (its square) before any stage
# reads them, so one set of numbers suits any resolution.
REFERENCE_FOCAL_PX = 1000.0


def thresholds_in_pixels(thresholds, focal_px: Float[Array, ""], units: dict[str, str]):
    """``thresholds`` (a :class:`ThresholdsBase`) with its lengths given in pixels of a
    ``REFERENCE_FOCAL_PX`` camera turned into pixels of this rig (``focal_px``: its focal
    length, pixels); ``units`` maps a field to ``"px"``, ``"px2"`` or anything else (kept)."""
    scale = focal_px / REFERENCE_FOCAL_PX
    power = {"px": 1, "px2": 2}
    return thresholds._replace(
        **{
            name: getattr(thresholds, name) * scale ** power[unit]
            for name, unit in units.items()
            if unit in power
        }
    )


def gauss_coverage(alpha_tau: Float[Array, ""]) -> Float[Array, ""]:
    """``P(|Z| < alpha_tau) = erf(alpha_tau / √2)``: the share of Gaussian true pairs within
    ``alpha_tau · √2 σ``; the fitted gate is this quantile of the observed distances."""
    return erf(alpha_tau / jnp.sqrt(2.0))
