"""Greedy epipolar matching: cheapest pairwise edges first, merged under view-uniqueness.

After Shafique & Shah (2005), "A noniterative greedy algorithm for multiframe point
correspondence" (IEEE TPAMI 27(1)), who link points across frames by repeatedly taking the
best remaining edge of a weighted graph; here the frames are camera views and the weight is
epipolar.
"""

import dataclasses
from typing import ClassVar

import jax.numpy as jnp

from .._method import GroupTableMethod, register_method
from .._types import Array, Bool, Float, Int
from ..geometry._camera import Rig
from ..graph._groups import groups_from_labels
from ._candidates import nearest_candidates, symmetric_cost
from ._merge import merge_in_order


@dataclasses.dataclass(frozen=True)
class GreedyOptions:
    """Greedy epipolar matching (Shafique & Shah, 2005, adapted to views).

    Candidate edges join detections of different views whose symmetric epipolar cost
    ``½ (d[m, i, n, j] + d[n, j, m, i])`` is below the shared σ-matched gate
    ``τ = max(2·√2·σ, 1 px)``. To keep the edge list static and small, each detection keeps
    only its ``candidates_per_view`` cheapest partners in each other view, so there are at
    most ``E = N · (M − 1) · candidates_per_view`` edges (``N = M · P``). Edges are visited
    cheapest first (ties: smaller node pair first); an edge merges the two groups of its ends
    unless the merged group would hold two detections of one view. Every visited edge is
    decided once: no bound can be reached and the status is always 0.

    Attributes:
        candidates_per_view: static ``K ≥ 1``; the cheapest partners kept per detection and
            other view.
    """

    candidates_per_view: int = 2
    THRESHOLDS: ClassVar[tuple[str, ...]] = ()

    def __post_init__(self):
        k = self.candidates_per_view
        if not isinstance(k, int) or isinstance(k, bool) or k < 1:
            raise ValueError(f"GreedyOptions.candidates_per_view must be an int >= 1; got {k!r}")


def greedy_groups(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    mask: Bool[Array, "M P"],
    d: Float[Array, "M P M P"],
    tau: Float[Array, ""],
    sigma: Float[Array, ""],
    thresholds: dict[str, Float[Array, ""]],
    options: GreedyOptions,
) -> tuple[Int[Array, "G M"], Bool[Array, " G"], Int[Array, ""]]:
    """Groups ``(G, M)`` (slot per view or -1), ``valid (G,)`` and status ``()`` (always 0)
    of greedy epipolar matching; ``d (M, P, M, P)`` epipolar distances (px), ``tau`` the gate
    (px). ``rig``, ``xy`` and ``sigma`` are not used beyond the gate (it is given)."""
    del rig, xy, sigma, thresholds
    M, P = mask.shape
    N = M * P
    if M < 2:
        return groups_from_labels(jnp.arange(N, dtype=jnp.int32), jnp.zeros((N,), bool), M, P) + (
            jnp.int32(0),
        )
    c = symmetric_cost(d, mask)
    src, dst, cost, ok = nearest_candidates(c, tau, options.candidates_per_view)
    lo, hi = jnp.minimum(src, dst), jnp.maximum(src, dst)
    order = jnp.lexsort((hi, lo, jnp.where(ok, cost, jnp.inf)))
    lo, hi = lo[order], hi[order]
    labels = merge_in_order(lo, hi, jnp.sum(ok, dtype=jnp.int32), mask, freeze_on_conflict=False)
    groups, valid = groups_from_labels(labels, mask.reshape(N), M, P)
    return groups, valid, jnp.int32(0)


@dataclasses.dataclass(frozen=True)
class Greedy(GroupTableMethod, GreedyOptions):
    """Greedy epipolar matching as a registered method (``"greedy"``): the options and algorithm of
    :class:`GreedyOptions`, with the σ, gate, triangulation and validity gate every group-table
    method shares (:class:`cdog_jax.GroupTableMethod`).
    """

    GROUPS = staticmethod(greedy_groups)


register_method("greedy", Greedy)
