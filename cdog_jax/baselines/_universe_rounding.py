"""Rounding a soft node-to-node matching matrix to view-unique groups (shared by the matrix
baselines).

Input: a symmetric similarity ``S (N, N)`` that is ≈ 1 between detections of one object
and ≈ 0 otherwise (a cosine of spectral embeddings, or a relaxed matching matrix), and a
threshold (½ by default in the callers: halfway between "same" and "different").

1. *Universe (anchors).* Nodes are visited by decreasing degree ``Σ_j S[u, j]`` (ties:
   smallest index); the first node not yet covered becomes an anchor, and it covers every
   node whose similarity to it exceeds the threshold. Each anchor is one object of the
   universe; every valid node is covered, so the loop ends after at most ``N`` anchors.
2. *Per-view assignment.* In every view, detections are assigned to anchors by a bounded
   greedy assignment (Hungarian is not available in JAX): repeatedly take the pair
   (detection, anchor) of highest similarity above the threshold, assign it and retire
   both; at most ``P`` rounds (a view has ``P`` slots), so the bound is exact.
3. Detections sharing an anchor form a group; groups of one detection are dropped.

Every group is view-unique by construction (step 2 uses an anchor at most once per view).
"""

import jax
import jax.numpy as jnp

from .._types import Array, Bool, Float, Int
from ..graph._groups import groups_from_labels


def choose_anchors(
    S: Float[Array, "N N"], valid: Bool[Array, " N"], threshold: Float[Array, ""]
) -> Bool[Array, " N"]:
    """``(N,)`` True at the anchors (step 1 of the module docstring)."""
    N = S.shape[0]
    degree = jnp.sum(jnp.where(valid[None, :], S, 0.0), axis=1)
    node = jnp.arange(N, dtype=jnp.int32)

    def cond(carry):
        _, covered, it = carry
        return jnp.any(valid & ~covered) & (it < N)

    def body(carry):
        is_anchor, covered, it = carry
        free = valid & ~covered
        key = jnp.where(free, degree, -jnp.inf)
        best = jnp.max(key)
        a = jnp.min(jnp.where(free & (key == best), node, N))
        covered = covered | (valid & (S[a] > threshold)) | (node == a)
        return is_anchor | (node == a), covered, it + 1

    init = (jnp.zeros((N,), bool), ~valid, jnp.int32(0))
    is_anchor, _, _ = jax.lax.while_loop(cond, body, init)
    return is_anchor


def assign_per_view(
    S: Float[Array, "N N"],
    valid: Bool[Array, " N"],
    is_anchor: Bool[Array, " N"],
    threshold: Float[Array, ""],
    num_views: int,
    num_slots: int,
) -> Int[Array, " N"]:
    """``(N,)`` the anchor (a node index) of each node, or -1 (step 2)."""
    M, P = num_views, num_slots
    N = M * P
    ok = valid[:, None] & is_anchor[None, :] & (S > threshold)
    score = jnp.where(ok, S, -jnp.inf).reshape(M, P, N)
    flat_index = jnp.arange(P * N, dtype=jnp.int32).reshape(P, N)

    def body(_, carry):
        score, anchor_of = carry
        flat = score.reshape(M, P * N)
        best = jnp.max(flat, axis=1)  # (M,)
        # Highest score, ties to the smallest (slot, anchor) index.
        pick = jnp.min(
            jnp.where(flat == best[:, None], flat_index.reshape(1, P * N), P * N), axis=1
        )
        found = best > -jnp.inf
        slot, anchor = pick // N, pick % N
        view = jnp.arange(M, dtype=jnp.int32)
        anchor_of = anchor_of.at[view, jnp.where(found, slot, P)].set(anchor, mode="drop")
        slot_hit = jnp.arange(P, dtype=jnp.int32)[None, :] == slot[:, None]  # (M, P)
        anchor_hit = jnp.arange(N, dtype=jnp.int32)[None, :] == anchor[:, None]  # (M, N)
        retire = found[:, None, None] & (slot_hit[:, :, None] | anchor_hit[:, None, :])
        return jnp.where(retire, -jnp.inf, score), anchor_of

    anchor_of = jnp.full((M, P), -1, jnp.int32)
    _, anchor_of = jax.lax.fori_loop(0, P, body, (score, anchor_of))
    return anchor_of.reshape(N)


def groups_from_anchors(
    anchor_of: Int[Array, " N"], num_views: int, num_slots: int
) -> tuple[Int[Array, "G M"], Bool[Array, " G"]]:
    """The ``(G, M)`` group table (``G = N // 2``) of nodes sharing an anchor (step 3)."""
    N = anchor_of.shape[0]
    node = jnp.arange(N, dtype=jnp.int32)
    assigned = anchor_of >= 0
    # Label each node by the smallest node of its anchor's set, as groups_from_labels expects.
    smallest = (
        jnp.full((N,), N, jnp.int32).at[jnp.where(assigned, anchor_of, N)].min(node, mode="drop")
    )
    labels = jnp.where(assigned, smallest[jnp.maximum(anchor_of, 0)], node)
    return groups_from_labels(labels, assigned, num_views, num_slots)


def round_to_groups(
    S: Float[Array, "N N"],
    valid: Bool[Array, " N"],
    threshold: Float[Array, ""],
    num_views: int,
    num_slots: int,
) -> tuple[Int[Array, "G M"], Bool[Array, " G"]]:
    """Steps 1–3 of the module docstring: the view-unique group table of ``S``."""
    N = S.shape[0]
    S = jnp.where(valid[:, None] & valid[None, :], S, 0.0)
    S = jnp.where(jnp.eye(N, dtype=bool) & valid[:, None], 1.0, S)  # a node is its own best match
    is_anchor = choose_anchors(S, valid, threshold)
    anchor_of = assign_per_view(S, valid, is_anchor, threshold, num_views, num_slots)
    return groups_from_anchors(anchor_of, num_views, num_slots)
