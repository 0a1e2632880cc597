"""Pipeline configuration (docs/ALGORITHM.md): static structure plus traced numeric thresholds.

:class:`Config` holds plain Python values, so it is hashable and can be a static argument
of ``jax.jit``. Its numeric fields (τ, δ, α, the jump rule...) are *not* part of the jit
key: :meth:`Config.thresholds` turns them into a :class:`Thresholds` pytree of arrays that
the pipeline receives as a traced input, so a sweep over them (or over σ) compiles once.
"""

from __future__ import annotations

import dataclasses
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


@dataclasses.dataclass(frozen=True)
class Config:
    """How to associate. Structural fields change the compiled program; numeric ones do not.

    Presets: :meth:`paper` (the paper's method, our defaults) and :meth:`reference` (the
    original public implementation's behaviour, docs/BENCHMARK.md §5).
    """

    # --- structure (part of the jit key) ---
    adjacency: Adjacency = "mutual"
    prune_scope: PruneScope = "all"
    iqr: bool = True
    iqr_score: IqrScore = "exclude_own"
    iqr_quartiles: IqrQuartiles = "zero_pad"
    iqr_guards: bool = False  # reference's 10 px / 50 px rules
    second_association: bool = False
    recover: bool = False  # attach leftovers to groups by reprojection (beyond the paper)
    regroup: bool = False  # run Alg. 1-3 again on what is left (beyond the paper)
    support_filter: bool = False  # drop groups that views seeing their point do not detect
    bpe_filter: bool = True
    refine: bool = False
    sigma_mode: SigmaMode = "given"
    max_split_iters: int = 64
    max_iqr_iters: int = 16
    refine_max_steps: int = 20
    jump_min_gaps: int = 3  # gaps needed before a jump can be declared
    # --- numeric defaults (become a traced Thresholds) ---
    alpha_tau: float = 2.0
    tau_min_px: float = 1.0
    delta: float = 0.5
    iqr_alpha: float = 2.0
    iqr_floor_px: float = 1.0
    iqr_min_px: float = 10.0
    iqr_force_px: float = 50.0
    jump_kappa: float = 10.0
    jump_floor_px2: float = 4.0
    jump_floor_sigma: float = 3.0
    second_frac: float = 0.5
    recover_frac: float = 1.0
    support_frac: float = 3.0
    support_alpha: float = 0.01
    support_min_rate: float = 0.02
    support_ref_views: float = 4.0
    # The validity gate every valid group passes (ALGORITHM.md §12). 1° is far below the
    # parallax of any benchmark group and well above what float32 can triangulate; 3 τ
    # leaves room above recovery's attach gate (recover_frac · τ, 2 τ in extended()).
    min_parallax_deg: float = 1.0
    max_err_frac: float = 3.0

    def __post_init__(self):
        choices = {
            "adjacency": ("mutual", "union"),
            "prune_scope": ("all", "conflicts", "none"),
            "iqr_score": ("exclude_own", "include_own"),
            "iqr_quartiles": ("zero_pad", "positive"),
            "sigma_mode": ("given", "auto"),
        }
        for name, allowed in choices.items():
            if getattr(self, name) not in allowed:
                raise ValueError(f"Config.{name} must be one of {allowed}; got {getattr(self, name)!r}")
        for name in ("max_split_iters", "max_iqr_iters", "refine_max_steps", "jump_min_gaps"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ValueError(f"Config.{name} must be a positive int; got {value!r}")
        for field in dataclasses.fields(self):
            if field.type == "bool" and not isinstance(getattr(self, field.name), bool):
                raise TypeError(f"Config.{field.name} must be True or False; got {getattr(self, field.name)!r}")
        for name in _NUMERIC:
            check_number(getattr(self, name), name, "Config")

    @classmethod
    def paper(cls, **overrides) -> "Config":
        """The paper's C-DOG (Alg. 1–3 and §IV-E) with noise-matched τ."""
        return cls(**overrides)

    @classmethod
    def extended(cls, **overrides) -> "Config":
        """Beyond the paper: union adjacency, then leftover detections are attached to groups
        by reprojection (``recover``) and what is still left is associated again
        (``regroup``). Recovers most points the paper's pruning loses (2-view points above all)."""
        base = dict(adjacency="union", recover=True, recover_frac=2.0, regroup=True)
        base.update(overrides)
        return cls(**base)

    @classmethod
    def reference(cls, **overrides) -> "Config":
        """The original public code's choices (docs/BENCHMARK.md §5): fixed τ = 10 px, δ-pruning only of
        view-conflicting components, IQR α = 1.5 on positive scores with own errors and the
        10/50 px guards, no BPE filter, then the second association."""
        base = dict(
            adjacency="mutual",
            prune_scope="conflicts",
            iqr_alpha=1.5,
            iqr_floor_px=0.0,
            iqr_score="include_own",
            iqr_quartiles="positive",
            iqr_guards=True,
            bpe_filter=False,
            second_association=True,
            alpha_tau=0.0,
            tau_min_px=10.0,
        )
        base.update(overrides)
        return cls(**base)

    def replace(self, **changes) -> "Config":
        """A copy with ``changes`` applied; checked like a new Config."""
        return dataclasses.replace(self, **changes)

    def thresholds(self, sigma_px=0.0, *, dtype=None) -> Thresholds:
        """The numeric fields (and σ) as a :class:`Thresholds` of scalar arrays.

        NumPy scalars (cheap to pass to a jitted function), except that a JAX ``sigma_px``
        (traced, or batched) stays a JAX array.
        """
        dtype = np.dtype(jax.dtypes.canonicalize_dtype(dtype or jnp.float32))
        values = {name: np.asarray(getattr(self, name), dtype) for name in _NUMERIC}
        sigma = jnp.asarray(sigma_px, dtype) if isinstance(sigma_px, jax.Array) else np.asarray(sigma_px, dtype)
        return Thresholds(sigma_px=sigma, **values)

    def structure(self) -> "Config":
        """This config with its numeric fields reset to the defaults: the part a jit key needs."""
        defaults = Config()
        return dataclasses.replace(self, **{name: getattr(defaults, name) for name in _NUMERIC})


PRESETS = ("paper", "extended", "reference")


def config_from(config, function: str) -> Config:
    """A :class:`Config`, or the preset it names (``"paper"``, ``"extended"``, ``"reference"``)."""
    if isinstance(config, Config):
        return config
    if isinstance(config, str):
        if config not in PRESETS:
            raise ValueError(f"{function}: config must be a Config or a preset name {PRESETS}; got {config!r}")
        return getattr(Config, config)()
    raise TypeError(f"{function}: config must be a Config or a preset name {PRESETS}; got {type(config).__name__}")


def tau_px(th: Thresholds, sigma_px: Float[Array, ""]) -> Float[Array, ""]:
    """Epipolar gate ``τ = max(alpha_tau · √2 · σ, tau_min)`` in pixels (docs/ALGORITHM.md §1–2)."""
    return jnp.maximum(th.alpha_tau * jnp.sqrt(2.0) * sigma_px, th.tau_min_px)
