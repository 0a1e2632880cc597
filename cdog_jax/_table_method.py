"""Methods that only decide the groups: the shared σ, gate, triangulation and validity gate
around a group-table function (docs/ARCHITECTURE.md, "How to add a method").

A subclass of :class:`GroupTableMethod` is a frozen dataclass whose ``float`` fields are its
numbers (traced) and whose other fields are its structure (static), and which implements
:meth:`GroupTableMethod.group_table`. Everything else is shared, so that every such method
is compared on equal terms with C-DOG: the noise σ (given, or estimated from the epipolar
distances as C-DOG does), the σ-matched epipolar gate ``τ = max(alpha_tau·√2·σ,
tau_min_px)``, the multi-view DLT point of each group, and the validity gate
(ALGORITHM.md §12) before the :class:`~cdog_jax.Association` is built.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import ClassVar, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._method import Method, Observations
from ._result import Association, association_from_groups
from .cdog._stage import raise_flag
from ._status import Status
from ._types import Array, Bool, Float, Int
from .geometry._camera import Rig
from .geometry._epipolar import epipolar_distances
from .geometry._projection import group_errors
from .geometry._triangulate import triangulate_views_last
from .graph._groups import gather_groups
from .graph._sigma import estimate_sigma, focal_scale
from .graph._sigma_robust import estimate_sigma_robust
from .refine._validity import validity_gate

SIGMA_MODES = ("given", "auto", "robust")
"""Where a group-table method's σ comes from: the caller, or C-DOG's two estimators."""

_NUMBER_TYPES: dict[type, type] = {}


def _numeric_fields(cls: type) -> tuple[str, ...]:
    return tuple(f.name for f in dataclasses.fields(cls) if f.type in ("float", float))


def numbers_type(cls: type) -> type:
    """The ``NamedTuple`` of ``cls``'s numbers: ``sigma_px`` then its ``float`` fields (one
    type per class, made once)."""
    if cls not in _NUMBER_TYPES:
        fields = [("sigma_px", Float[Array, ""])] + [(name, Float[Array, ""]) for name in _numeric_fields(cls)]
        _NUMBER_TYPES[cls] = NamedTuple(f"{cls.__name__}Thresholds", fields)
    return _NUMBER_TYPES[cls]


@dataclasses.dataclass(frozen=True)
class GroupTableMethod(Method):
    """A method that makes the group table from the scene's epipolar distances.

    Shared fields: ``sigma_mode`` (``"given"``, ``"auto"`` or ``"robust"``: σ from the
    scene's epipolar distances by C-DOG's estimators, ALGORITHM.md §0.1–0.2), the gate ``alpha_tau`` and
    ``tau_min_px`` (px), and the validity gate's ``min_parallax_deg`` and ``max_err_frac``
    (as in :class:`cdog_jax.Config`).
    """

    sigma_mode: str = "given"
    alpha_tau: float = 2.0
    tau_min_px: float = 1.0
    min_parallax_deg: float = 1.0
    max_err_frac: float = 3.0

    def __post_init__(self):
        if self.sigma_mode not in SIGMA_MODES:
            raise ValueError(f"{type(self).__name__}.sigma_mode must be one of {SIGMA_MODES}; got {self.sigma_mode!r}")
        for name in _numeric_fields(type(self)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value < 0:
                raise ValueError(f"{type(self).__name__}.{name} must be a finite number >= 0; got {value!r}")
        later = getattr(super(), "__post_init__", None)  # an options base class's own checks
        if later is not None:
            later()

    #: A baseline written as a plain function ``f(rig, xy, mask, d, tau, sigma, numbers, options)``
    #: (``numbers``: ``{name: traced value}`` for the names in its ``NUMBERS``; ``options``: this
    #: method) sets it instead of overriding :meth:`group_table`.
    GROUPS: ClassVar[Callable | None] = None

    def group_table(
        self,
        rig: Rig,
        xy: Float[Array, "M P 2"],
        mask: Bool[Array, "M P"],
        d: Float[Array, "M P M P"],
        sigma: Float[Array, ""],
        tau: Float[Array, ""],
        thresholds: tuple,
    ) -> tuple[Int[Array, "G M"], Bool[Array, " G"], Int[Array, ""]]:
        """``groups (G, M)`` (slot per view or -1; ``G = M·P // 2``), ``valid (G,)`` and an
        int32 status. ``xy`` has its padding zeroed; ``d[m, i, n, j]`` is the distance (px)
        in image n from detection ``(n, j)`` to the epipolar line of ``(m, i)`` (``+inf``
        within a view and for padding); ``tau`` is the σ-matched gate (px). A valid group
        has ≥ 2 members, at most one per view, and groups are disjoint."""
        if self.GROUPS is None:
            raise NotImplementedError(f"{type(self).__name__} must override group_table or set GROUPS")
        numbers = {name: getattr(thresholds, name) for name in getattr(self, "NUMBERS", ())}
        return type(self).GROUPS(rig, xy, mask, d, tau, sigma, numbers, self)

    def structure(self) -> "GroupTableMethod":
        defaults = type(self)()
        return dataclasses.replace(self, **{name: getattr(defaults, name) for name in _numeric_fields(type(self))})

    def thresholds(self, sigma_px=0.0, *, dtype=None) -> tuple:
        dtype = np.dtype(jax.dtypes.canonicalize_dtype(dtype or jnp.float32))
        sigma = jnp.asarray(sigma_px, dtype) if isinstance(sigma_px, jax.Array) else np.asarray(sigma_px, dtype)
        values = {name: np.asarray(getattr(self, name), dtype) for name in _numeric_fields(type(self))}
        return numbers_type(type(self))(sigma_px=sigma, **values)

    def associate_scene(self, rig: Rig, observations: Observations, thresholds: tuple) -> Association:
        th = type(thresholds)(*(jnp.asarray(v) for v in thresholds))
        xy, d, sigma, tau, fallback = scene_gate(rig, observations, th, self.sigma_mode)
        groups, valid, status = self.group_table(rig, xy, observations.mask, d, sigma, tau, th)
        return finish_table(rig, xy, groups, valid, status | raise_flag(fallback, Status.SIGMA_FALLBACK), sigma, tau, th)


def scene_gate(
    rig: Rig, observations: Observations, th: tuple, sigma_mode: str
) -> tuple[Float[Array, "M P 2"], Float[Array, "M P M P"], Float[Array, ""], Float[Array, ""], Bool[Array, ""]]:
    """What every group-table method starts from: ``xy (M, P, 2)`` with padding zeroed, the
    epipolar distances ``d (M, P, M, P)`` (px), σ (given, or estimated when ``sigma_mode``
    is ``"auto"`` or ``"robust"``), the σ-matched gate τ (px) and whether the estimate fell back."""
    mask = observations.mask
    xy = jnp.where(mask[..., None], observations.xy, 0.0)
    d = epipolar_distances(rig, xy, mask)
    if sigma_mode == "auto":
        sigma, fallback = estimate_sigma(d, mask, focal_scale(rig.K))
    elif sigma_mode == "robust":
        sigma, fallback = estimate_sigma_robust(d, mask, focal_scale(rig.K))
    else:
        sigma, fallback = th.sigma_px, jnp.asarray(False)
    tau = jnp.maximum(th.alpha_tau * jnp.sqrt(2.0) * sigma, th.tau_min_px)
    return xy, d, sigma, tau, fallback


def finish_table(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    groups: Int[Array, "G M"],
    valid: Bool[Array, " G"],
    status: Int[Array, ""],
    sigma: Float[Array, ""],
    tau: Float[Array, ""],
    th: tuple,
) -> Association:
    """The :class:`~cdog_jax.Association` of a group table ``(G, M)``: every valid group's
    multi-view DLT point, the validity gate (with ``th.max_err_frac`` and
    ``th.min_parallax_deg``), its errors; ``xy (M, P, 2)`` pixels (padding zeroed)."""
    P = xy.shape[1]
    member = valid[:, None] & (groups >= 0)
    xy_g = gather_groups(groups, xy)
    X, _ = triangulate_views_last(rig, xy_g, member)
    member, valid, X = validity_gate(rig, xy_g, member, X, tau, th.max_err_frac, th.min_parallax_deg)
    bpe, err_px = group_errors(rig, X, xy_g, member)
    return association_from_groups(
        groups, valid, member, X, bpe, err_px, P, jnp.asarray(sigma, xy.dtype), jnp.asarray(tau, xy.dtype), status
    )
