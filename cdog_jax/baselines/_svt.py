"""Low-rank, cycle-consistent matching by singular-value thresholding (matchSVT).

Source: X. Zhou, M. Zhu and K. Daniilidis (2015), "Multi-image matching via fast
alternating minimization" (ICCV), in the form that J. Dong et al. (2019), "Fast and robust
multi-person 3D pose estimation from multiple views" (mvpose, CVPR) and EasyMocap use to
match detections across cameras: relax the cycle-consistent partial-permutation matrix to
a matrix ``X (N, N)`` with entries in ``[0, 1]``, reward agreement with the measured pairwise
affinities and penalise rank through the nuclear norm.

As implemented here, with ``W`` the epipolar affinity of ``_epipolar_affinity`` (a Gaussian
of the symmetric epipolar distance inside the σ-matched gate ``τ``, scale
``affinity_width·τ``):

    minimise  −⟨W, X⟩ + λ ‖Y‖_*   subject to  X = Y,  X ∈ C,

where ``C`` holds the symmetric matrices with entries in ``[0, 1]``, the identity on the
diagonal of valid detections, 0 between two slots of one view and on padding. ADMM on the
augmented Lagrangian with penalty ``μ`` and multiplier ``Λ`` repeats, a fixed number of times
(``iterations``, static):

1. ``Y ← SVT_{λ/μ}(X + Λ/μ)``: singular-value thresholding; the argument is symmetric, so
   its SVD comes from ``eigh`` (singular values ``|e|``, each shrunk by ``λ/μ``, sign kept);
2. ``X ← Π_C(Y + (W − Λ)/μ)``: the projection onto ``C`` (symmetrise, clip, fix the
   diagonal blocks);
3. ``Λ ← Λ + μ (X − Y)``.

It starts from ``X = Y = Π_C(W)``, ``Λ = 0``. The fixed count is the method's definition (as
in mvpose), not a bound that can be hit, so the status is always 0. Rounding: ``X``
(≈ 1 within an object) goes to the shared universe rounding (``_universe_rounding``:
anchors by decreasing degree, per-view bounded greedy assignment above
``similarity_threshold``).

Cost: one ``N × N`` eigendecomposition per iteration, ``O(iterations · N³)``: the slowest
of the matrix baselines (docs/ALGORITHM.md gives measured times).
"""

import dataclasses
from typing import ClassVar

import jax
import jax.numpy as jnp

from .._method import GroupTableMethod, register_method
from .._types import Array, Bool, Float, Int
from ..geometry._camera import Rig
from ._epipolar_affinity import epipolar_affinity
from ._universe_rounding import round_to_groups


@dataclasses.dataclass(frozen=True)
class MatchSVTOptions:
    """Parameters of matchSVT (Zhou, Zhu & Daniilidis 2015; as in mvpose, Dong et al. 2019).

    Attributes:
        iterations: static number of ADMM iterations.
        affinity_width: affinity scale as a fraction of the gate ``τ`` (traced).
        rank_weight: ``λ``, the weight of the nuclear norm against the affinity reward
            (traced). With the diagonal fixed to 1, ``‖X‖_*`` equals the trace (a constant)
            for a positive semi-definite ``X``, so the term penalises the negative
            eigenvalues that inconsistent cycles create. Chosen on 20-point scenes (pair
            precision / recall): 5 views at σ = 1 px, λ = 0.5 gave 0.83 / 0.79, 1 gave
            0.86 / 0.83, 2–5 gave 0.96 / 0.95, 10 gave 0.97 / 0.95; 10 views at σ = 3 px,
            λ = 3 gave 0.93 / 0.91, 6 and 10 gave 0.98 / 0.98.
        penalty: ``μ``, the ADMM penalty (traced).
        similarity_threshold: entries of ``X`` above it may join two detections in the
            rounding (traced).
    """

    iterations: int = 50
    affinity_width: float = 1.0
    rank_weight: float = 10.0
    penalty: float = 4.0
    similarity_threshold: float = 0.5
    THRESHOLDS: ClassVar[tuple[str, ...]] = (
        "affinity_width",
        "rank_weight",
        "penalty",
        "similarity_threshold",
    )

    def __post_init__(self):
        if not isinstance(self.iterations, int) or self.iterations < 0:
            raise ValueError(
                f"MatchSVTOptions.iterations must be an int >= 0; got {self.iterations!r}"
            )


def _project(A, allowed, diagonal):
    """``Π_C``: symmetrise, clip to ``[0, 1]``, 0 where not ``allowed``, 1 on ``diagonal``."""
    A = jnp.clip(0.5 * (A + A.T), 0.0, 1.0)
    return jnp.where(diagonal, 1.0, jnp.where(allowed, A, 0.0))


def _shrink_singular_values(A, threshold):
    """SVT of a symmetric ``A``: each eigenvalue ``e`` becomes ``sign(e)·max(|e| − t, 0)``."""
    e, V = jnp.linalg.eigh(0.5 * (A + A.T))
    e = jnp.sign(e) * jnp.maximum(jnp.abs(e) - threshold, 0.0)
    return (V * e[None, :]) @ V.T


def match_svt_groups(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    mask: Bool[Array, "M P"],
    d: Float[Array, "M P M P"],
    tau: Float[Array, ""],
    sigma: Float[Array, ""],
    thresholds: dict[str, Float[Array, ""]],
    options: MatchSVTOptions,
) -> tuple[Int[Array, "G M"], Bool[Array, " G"], Int[Array, ""]]:
    """matchSVT groups of one scene (module docstring): ``groups (G, M)`` (slot or -1),
    ``valid (G,)`` with ``G = M·P // 2``, and status 0."""
    M, P = mask.shape
    N = M * P
    dtype = d.dtype
    width, rank_weight, penalty, similarity_threshold = (
        jnp.asarray(thresholds[name], dtype) for name in MatchSVTOptions.THRESHOLDS
    )
    valid = mask.reshape(N)
    view = jnp.arange(N, dtype=jnp.int32) // P
    allowed = valid[:, None] & valid[None, :] & (view[:, None] != view[None, :])
    diagonal = jnp.eye(N, dtype=bool) & valid[:, None]
    W = epipolar_affinity(d, mask, jnp.asarray(tau, dtype), width)

    def step(_, carry):
        X, Lam = carry
        Y = _shrink_singular_values(X + Lam / penalty, rank_weight / penalty)
        X = _project(Y + (W - Lam) / penalty, allowed, diagonal)
        return X, Lam + penalty * (X - Y)

    X0 = _project(W, allowed, diagonal)
    X, _ = jax.lax.fori_loop(0, options.iterations, step, (X0, jnp.zeros_like(W)))
    groups, group_valid = round_to_groups(X, valid, similarity_threshold, M, P)
    return groups, group_valid, jnp.int32(0)


@dataclasses.dataclass(frozen=True)
class MatchSVT(GroupTableMethod, MatchSVTOptions):
    """Low-rank cycle-consistent matching by singular-value thresholding (matchSVT) as a registered method (``"match_svt"``): the options and algorithm of
    :class:`MatchSVTOptions`, with the σ, gate, triangulation and validity gate every group-table
    method shares (:class:`cdog_jax.GroupTableMethod`).
    """

    GROUPS = staticmethod(match_svt_groups)


register_method("match_svt", MatchSVT)
