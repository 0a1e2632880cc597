"""C-DOG's numbers (docs/ALGORITHM.md): the traced :class:`Thresholds`, their allowed
ranges, and the epipolar gate τ.

:class:`cdog_jax.Config` (``_cdog.py``) holds plain Python values, so it is hashable and can
be a static argument of ``jax.jit``. Its numeric fields (τ, δ, α, the jump rule...) are
*not* part of the jit key: :meth:`Config.thresholds` turns them into a :class:`Thresholds`
pytree of arrays that the pipeline receives as a traced input, so a sweep over them (or
over σ) compiles once.
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._types import Array, Float

Adjacency = Literal["mutual", "union"]
PruneScope = Literal["all", "conflicts", "none"]
IqrScore = Literal["exclude_own", "include_own"]
IqrQuartiles = Literal["zero_pad", "positive"]
SigmaMode = Literal["given", "auto"]


class Thresholds(NamedTuple):
    """Numeric thresholds, traced (scalars, or arrays with a leading batch axis under vmap).

    ``tau_px = max(alpha_tau * sqrt(2) * sigma_px, tau_min_px)`` (docs/ALGORITHM.md §1–2).
    """

    sigma_px: Float[Array, ""]  # 2D noise std (pixels); ignored when sigma_mode="auto"
    alpha_tau: Float[Array, ""]
    tau_min_px: Float[Array, ""]
    delta: Float[Array, ""]  # δ-overlap threshold (Alg. 2)
    iqr_alpha: Float[Array, ""]  # IQR fence multiplier (Alg. 3)
    iqr_floor_px: Float[Array, ""]  # an outlier's score must also exceed this (pixels)
    iqr_min_px: Float[Array, ""]  # reference guard: no outlier if max score below this
    iqr_force_px: Float[Array, ""]  # reference guard: drop the max if above this
    jump_kappa: Float[Array, ""]  # BPE jump: gap > kappa * median(previous gaps)
    jump_floor_px2: Float[Array, ""]  # BPE jump: gap > floor_px2 + (floor_sigma * sigma)^2
    jump_floor_sigma: Float[Array, ""]
    second_frac: Float[Array, ""]  # second association: attach if mean cost < frac * tau
    recover_frac: Float[Array, ""]  # recovery: attach if reprojection error < frac * tau
    support_frac: Float[Array, ""]  # support filter: a detection within frac * tau explains a view
    support_alpha: Float[Array, ""]  # support filter: drop if P(that many misses) < alpha
    support_min_rate: Float[Array, ""]  # support filter: floor of the estimated miss rate
    support_ref_views: Float[Array, ""]  # support filter: members of the groups that estimate it
    min_parallax_deg: Float[Array, ""]  # validity gate: largest angle between members' lines of sight
    max_err_frac: Float[Array, ""]  # validity gate: every member's reprojection error <= frac * tau
    seed_frac: Float[Array, ""]  # seeding: a detection within frac * tau votes for a two-view point
    reassign_frac: Float[Array, ""]  # re-assignment: a detection joins its nearest point within frac * tau


DEFAULT_MIN_PARALLAX_DEG = 1.0
"""The validity gate's default parallax bound (degrees; ``Config.min_parallax_deg``)."""

_NUMERIC = tuple(f for f in Thresholds._fields if f != "sigma_px")


class Range(NamedTuple):
    """Allowed values of a numeric field: finite, ``low <= v`` (``<`` if ``low_open``) and
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
        lo, hi = "(" if self.low_open else "[", ")" if self.high_open or self.high == float("inf") else "]"
        return f"finite and in {lo}{self.low:g}, {self.high:g}{hi}"


# Every numeric field of Config and Thresholds (σ included): a new field adds its line.
RANGES: dict[str, Range] = {
    "sigma_px": Range(),
    "alpha_tau": Range(),
    "tau_min_px": Range(),
    "delta": Range(0.0, 1.0, low_open=True),  # θ ≥ δ keeps an edge; δ = 0 would keep all
    "iqr_alpha": Range(),
    "iqr_floor_px": Range(),
    "iqr_min_px": Range(),
    "iqr_force_px": Range(),
    "jump_kappa": Range(),
    "jump_floor_px2": Range(),
    "jump_floor_sigma": Range(),
    "second_frac": Range(),
    "recover_frac": Range(),
    "support_frac": Range(),
    "support_alpha": Range(0.0, 1.0),  # a probability
    "support_min_rate": Range(0.0, 1.0),  # a miss rate
    "support_ref_views": Range(),
    "min_parallax_deg": Range(0.0, 90.0, high_open=True),  # validity gate, degrees
    "max_err_frac": Range(0.0, low_open=True),  # validity gate, a multiple of τ
    "seed_frac": Range(0.0, low_open=True),  # seeding's vote gate, a multiple of τ
    "reassign_frac": Range(0.0, low_open=True),  # re-assignment's gate, a multiple of τ
}


def check_number(value, name: str, where: str) -> None:
    """Raise unless ``value`` (a real number) is in ``RANGES[name]``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{where}.{name} must be a real number; got {type(value).__name__} {value!r}")
    allowed = RANGES.get(name, Range(-float("inf")))
    if not allowed.ok(value):
        raise ValueError(f"{where}.{name} must be {allowed.describe()}; got {value!r}")


def check_thresholds(th: "Thresholds", *, skip: tuple[str, ...] = ("sigma_px",)) -> None:
    """Raise if a concrete value of ``th`` (scalars or arrays) is outside its range; names
    the field, the value and, for arrays, the index. Traced values are not checked."""
    if not isinstance(th, Thresholds):
        raise TypeError(f"thresholds must be a Thresholds (from Config.thresholds()); got {type(th).__name__}")
    for name, value in zip(Thresholds._fields, th):
        if name in skip or isinstance(value, jax.core.Tracer):
            continue
        host = np.asarray(value)
        if host.dtype == np.bool_ or not (np.issubdtype(host.dtype, np.floating) or np.issubdtype(host.dtype, np.integer)):
            raise TypeError(f"thresholds.{name} must be real numbers; got dtype {host.dtype}")
        allowed = RANGES.get(name, Range(-float("inf")))
        ok = allowed.ok(host)
        if not ok.all():
            where = tuple(int(i) for i in np.argwhere(~ok)[0])
            at = f" at index {where}" if where else ""
            raise ValueError(f"thresholds.{name} must be {allowed.describe()}; got {host[where].item()!r}{at}")


def tau_px(th: Thresholds, sigma_px: Float[Array, ""]) -> Float[Array, ""]:
    """Epipolar gate ``τ = max(alpha_tau · √2 · σ, tau_min)`` in pixels (docs/ALGORITHM.md §1–2)."""
    return jnp.maximum(th.alpha_tau * jnp.sqrt(2.0) * sigma_px, th.tau_min_px)
