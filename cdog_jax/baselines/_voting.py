"""Triangulation voting: two-view hypotheses, inliers by reprojection, greedy acceptance.

In the spirit of RANSAC (Fischler & Bolles, 1981, "Random sample consensus: a paradigm for
model fitting with applications to image analysis and automated cartography", CACM 24(6)):
a minimal sample (two detections) proposes a model (a 3D point) and the other views vote
for it; here the samples are not random but every gated epipolar pair, and the models are
accepted by consensus under view-uniqueness.
"""

import dataclasses
import math
from typing import ClassVar

import jax
import jax.numpy as jnp

from .._method import GroupTableMethod, register_method
from .._types import Array, Bool, Float, Int
from ..geometry._camera import Rig
from ..geometry._triangulate import dlt_blocks
from ..graph._groups import groups_from_labels
from ..refine._hypotheses import accepted_row, score_hypotheses
from ._candidates import nearest_candidates, symmetric_cost


@dataclasses.dataclass(frozen=True)
class VotingOptions:
    """Triangulation voting (RANSAC style; Fischler & Bolles, 1981).

    Hypotheses: every detection paired with its cheapest detection in each other view,
    when their symmetric epipolar cost ``½ (d[m, i, n, j] + d[n, j, m, i])`` is below the
    shared σ-matched gate ``τ = max(2·√2·σ, 1 px)``: ``H = N · (M − 1)`` of them at most
    (``N = M · P``). Each is triangulated by two-view DLT (it must be well conditioned and
    in front of both cameras) and reprojected into every other view where it lies in front;
    there, the nearest detection within ``reprojection_gate · τ`` pixels is an inlier.
    Hypotheses are ranked once, by inlier count (more first), then mean reprojection error
    over all members (smaller first), then index; in that order each hypothesis whose two
    detections are both still unused is accepted as a group of its pair and its inliers,
    recomputed among the detections still unused (the nearest unused one per view within
    the gate). Each detection joins at most one group. The loop steps from one accepted
    hypothesis to the next (at most ``G = N // 2`` of them), so its bound cannot be reached
    and the status is always 0.

    Attributes:
        reprojection_gate: traced; the inlier gate in units of ``τ`` (``2 τ ≈ 5.7 σ``:
            the reprojection of a two-view point scatters more than a detection does).
    """

    reprojection_gate: float = 2.0
    THRESHOLDS: ClassVar[tuple[str, ...]] = ("reprojection_gate",)

    def __post_init__(self):
        g = self.reprojection_gate
        if isinstance(g, bool) or not isinstance(g, (int, float)) or not math.isfinite(g) or g <= 0:
            raise ValueError(
                f"VotingOptions.reprojection_gate must be a finite number > 0; got {g!r}"
            )


def voting_groups(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    mask: Bool[Array, "M P"],
    d: Float[Array, "M P M P"],
    tau: Float[Array, ""],
    sigma: Float[Array, ""],
    thresholds: dict[str, Float[Array, ""]],
    options: VotingOptions,
) -> tuple[Int[Array, "G M"], Bool[Array, " G"], Int[Array, ""]]:
    """Groups ``(G, M)`` (slot per view or -1), ``valid (G,)`` and status ``()`` (always 0)
    of triangulation voting; ``xy (M, P, 2)`` pixels, ``d`` the epipolar distances (px),
    ``tau`` the gate (px), ``thresholds["reprojection_gate"]``. Valid groups come first,
    ordered by their smallest node ``m · P + i``, as in every method."""
    del sigma, options
    M, P = mask.shape
    N, G = M * P, max(M * P // 2, 1)
    if M < 2:  # no pair of views, no hypothesis
        return groups_from_labels(jnp.arange(N, dtype=jnp.int32), jnp.zeros((N,), bool), M, P) + (
            jnp.int32(0),
        )
    views = jnp.arange(M, dtype=jnp.int32)
    slots = jnp.arange(P, dtype=jnp.int32)
    xy = jnp.where(mask[..., None], xy, 0.0)  # padding is neutral before any arithmetic
    gate = thresholds["reprojection_gate"] * tau

    src, dst, cost, ok = nearest_candidates(symmetric_cost(d, mask), tau, 1)  # (H,)
    scored = score_hypotheses(rig, xy, mask, dlt_blocks(rig, xy), src, dst, ok, gate)
    ok, count, err = scored.ok, scored.count, scored.err
    hyp = jnp.arange(src.shape[0], dtype=jnp.int32)
    order = jnp.lexsort((hyp, err, -count))

    src, dst = src[order], dst[order]  # ranked; the unusable ones last
    xy_hat, vote_views = scored.xy_hat[order], scored.vote_views[order]
    num_ranked = jnp.sum(ok, dtype=jnp.int32)
    rank = jnp.arange(src.shape[0], dtype=jnp.int32)

    # Each step jumps to the next ranked hypothesis whose two detections are unused and
    # accepts it, so the loop runs once per group (not once per hypothesis); a step that
    # finds none ends it. Every acceptance uses two unused detections, so after G = N // 2
    # of them no hypothesis is left: the bound (as seeding's) ends nothing early.
    def cond(carry):
        _, _, num_groups, k = carry
        return (k < num_ranked) & (num_groups < G)

    def body(carry):
        used, groups, num_groups, k = carry
        flat = used.reshape(N)
        alive = (rank >= k) & (rank < num_ranked) & ~flat[src] & ~flat[dst]
        k = jnp.min(jnp.where(alive, rank, num_ranked))
        found = k < num_ranked
        h = jnp.minimum(k, src.shape[0] - 1)
        row = accepted_row(xy, mask, used, xy_hat[h], vote_views[h], src[h], dst[h], gate)
        groups = groups.at[num_groups].set(jnp.where(found, row, groups[num_groups]), mode="drop")
        used = used | (found & (slots[None, :] == row[:, None]))
        return used, groups, num_groups + found.astype(jnp.int32), k + 1

    init = (jnp.zeros((M, P), bool), jnp.full((G, M), -1, jnp.int32), jnp.int32(0), jnp.int32(0))
    _, groups, num_groups, _ = jax.lax.while_loop(cond, body, init)
    # Renumber as every method does: groups ordered by their smallest node m * P + i.
    member = (jnp.arange(G, dtype=jnp.int32) < num_groups)[:, None] & (groups >= 0)  # (G, M)
    node = jnp.where(member, views[None, :] * P + groups, N)  # N = no member
    root = jnp.min(node, axis=1)  # (G,)
    labels = (
        jnp.arange(N, dtype=jnp.int32).at[node.reshape(-1)].set(jnp.repeat(root, M), mode="drop")
    )
    groups, valid = groups_from_labels(labels, mask.reshape(N), M, P)
    return groups, valid, jnp.int32(0)


@dataclasses.dataclass(frozen=True)
class Voting(GroupTableMethod, VotingOptions):
    """Triangulation voting as a registered method (``"voting"``): the options and algorithm of
    :class:`VotingOptions`, with the σ, gate, triangulation and validity gate every group-table
    method shares (:class:`cdog_jax.GroupTableMethod`).
    """

    GROUPS = staticmethod(voting_groups)


register_method("voting", Voting)
