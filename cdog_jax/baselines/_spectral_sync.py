"""Spectral permutation synchronisation (MatchEIG).

Sources: D. Pachauri, R. Kondor and V. Singh (2013), "Solving the multi-way matching
problem by permutation synchronization" (NeurIPS); E. Maset, F. Arrigoni and A. Fusiello
(2017), "Practical and efficient multi-view matching" (ICCV), whose MatchEIG handles
partial matches and a universe size estimated from the spectrum.

The idea: if every detection were mapped to its object in a universe of ``k`` objects by a
partial permutation ``U_m (P, k)`` per view, the stacked ``U (N, k)`` would give a pairwise
matching matrix ``W = U Uᵀ`` whose non-zero eigenvalues are the object sizes (views that
see each object, 1 for an unmatched detection). So the leading eigenvectors of a measured
``W`` recover ``U`` up to a rotation, and detections of one object have parallel rows.

As implemented here:

1. ``W`` is the epipolar affinity of every pair of detections in different views (a
   Gaussian of the symmetric epipolar distance inside the σ-matched gate ``τ``, width
   ``affinity_width·τ``; see ``_epipolar_affinity``), with 1 on the diagonal of valid
   detections (each detection matches itself) and 0 for padding.
2. ``jnp.linalg.eigh`` of the ``N × N`` matrix (static size). The universe size ``k`` is the
   number of eigenvalues above ``eigen_threshold``, at most ``max_objects`` (static, default
   ``N // 2``). In the noise-free spectrum every eigenvalue is an object size: ≥ 2 for a
   matched object, exactly 1 for an unmatched detection, else 0; the default 1.5 sits in
   the eigengap between matched objects and unmatched detections (the latter need no
   column: they end as singletons). Unused eigenvectors are masked to 0, not sliced, so
   the shapes stay static.
3. Rounding: the cosine similarity of the rows of the rank-``k`` reconstruction
   ``W_k = V_k Λ_k V_kᵀ`` (equivalently of the rows of ``V_k Λ_k``; ≈ 1 within an object,
   ≈ 0 across; weighting by ``Λ_k`` keeps the weakest kept modes, which noise makes, from
   dominating) goes to the shared universe rounding (``_universe_rounding``): anchors by
   decreasing degree, then per view a bounded greedy assignment (not Hungarian) of
   detections to anchors above ``similarity_threshold`` (½). Detections sharing an anchor
   form a group, view-unique by construction.

Cost: one ``N × N`` symmetric eigendecomposition, ``O(N³)``: see docs/ALGORITHM.md for
the measured times (practical on the CPU up to a few hundred nodes).
"""

import dataclasses
from typing import ClassVar

import jax.numpy as jnp

from .._method import GroupTableMethod, register_method
from .._types import Array, Bool, Float, Int
from ..geometry._camera import Rig
from ._epipolar_affinity import epipolar_affinity
from ._universe_rounding import round_to_groups


@dataclasses.dataclass(frozen=True)
class SpectralSyncOptions:
    """Parameters of MatchEIG (Pachauri et al. 2013; Maset et al. 2017).

    Attributes:
        max_objects: static bound on the universe size ``k`` (default ``None``: ``N // 2``).
        affinity_width: affinity scale as a fraction of the gate ``τ`` (traced).
        eigen_threshold: eigenvalues above it count as objects (traced; 1.5 sits in the
            noise-free eigengap between matched objects, ≥ 2, and unmatched detections, 1).
        similarity_threshold: cosine of embedding rows above which two detections may share
            an object in the rounding (traced).
    """

    max_objects: int | None = None
    affinity_width: float = 1.0
    eigen_threshold: float = 1.5
    similarity_threshold: float = 0.5
    THRESHOLDS: ClassVar[tuple[str, ...]] = (
        "affinity_width",
        "eigen_threshold",
        "similarity_threshold",
    )

    def __post_init__(self):
        if self.max_objects is not None and (
            not isinstance(self.max_objects, int) or self.max_objects < 1
        ):
            raise ValueError(
                f"SpectralSyncOptions.max_objects must be None or an int >= 1; got {self.max_objects!r}"
            )


def spectral_sync_groups(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    mask: Bool[Array, "M P"],
    d: Float[Array, "M P M P"],
    tau: Float[Array, ""],
    sigma: Float[Array, ""],
    thresholds: dict[str, Float[Array, ""]],
    options: SpectralSyncOptions,
) -> tuple[Int[Array, "G M"], Bool[Array, " G"], Int[Array, ""]]:
    """MatchEIG groups of one scene (module docstring): ``groups (G, M)`` (slot or -1),
    ``valid (G,)`` with ``G = M·P // 2``, and status 0 (no loop here can stop early)."""
    M, P = mask.shape
    N = M * P
    dtype = d.dtype
    width, eigen_threshold, similarity_threshold = (
        jnp.asarray(thresholds[name], dtype) for name in SpectralSyncOptions.THRESHOLDS
    )
    valid = mask.reshape(N)
    W = epipolar_affinity(d, mask, jnp.asarray(tau, dtype), width)
    W = jnp.where(jnp.eye(N, dtype=bool) & valid[:, None], 1.0, W)
    eigenvalues, vectors = jnp.linalg.eigh(W)  # ascending
    eigenvalues, vectors = eigenvalues[::-1], vectors[:, ::-1]
    max_objects = N // 2 if options.max_objects is None else min(options.max_objects, N)
    rank = jnp.arange(N, dtype=jnp.int32)
    used = (eigenvalues > eigen_threshold) & (rank < max_objects)
    # Rows of V_k Λ_k: their inner products are those of the rows of the rank-k W_k.
    embedding = jnp.where(
        used[None, :max_objects], vectors[:, :max_objects] * eigenvalues[None, :max_objects], 0.0
    )
    norm = jnp.sqrt(jnp.sum(embedding * embedding, axis=1))
    ok = valid & (norm > jnp.sqrt(jnp.finfo(dtype).eps))
    unit = jnp.where(ok[:, None], embedding / jnp.where(ok, norm, 1.0)[:, None], 0.0)
    S = unit @ unit.T
    groups, group_valid = round_to_groups(S, valid, similarity_threshold, M, P)
    return groups, group_valid, jnp.int32(0)


@dataclasses.dataclass(frozen=True)
class SpectralSync(GroupTableMethod, SpectralSyncOptions):
    """Spectral permutation synchronisation (MatchEIG) as a registered method (``"spectral_sync"``): the options and algorithm of
    :class:`SpectralSyncOptions`, with the σ, gate, triangulation and validity gate every group-table
    method shares (:class:`cdog_jax.GroupTableMethod`).
    """

    GROUPS = staticmethod(spectral_sync_groups)


register_method("spectral_sync", SpectralSync)
