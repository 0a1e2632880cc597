"""The back-projection error of an association (docs/ALGORITHM.md §8) as a differentiable loss.

Given a group table, every group's 3D point is triangulated inside by the closed-form
multi-view DLT (no SVD, so the derivative is defined wherever the point is determined) or
given (joint optimisation of cameras and points). The loss is differentiable w.r.t. every
array of the rig, the pixels and the points; padded slots, invalid groups and degenerate
normal systems contribute neither values nor NaN gradients.
"""

import functools
from typing import Literal

import jax
import jax.numpy as jnp
from jaxtyping import ArrayLike, Real

from .._expect import ARRAY, expect_args
from .._types import Array, Bool, Float, Int
from ..geometry._camera import Rig
from ..geometry._projection import project_views_last
from ..geometry._triangulate import dlt_blocks_views_last, solve_normal_3x3
from ..graph._groups import gather_groups

Loss = Literal["l2", "huber", "cauchy"]
_LOSSES = ("l2", "huber", "cauchy")


def _rho(s: Float[Array, "*S"], loss: str, c: Float[Array, ""]) -> Float[Array, "*S"]:
    """Robust kernel, elementwise, of squared residuals ``s`` (px²), scale ``c`` (px)."""
    if loss == "l2":
        return s
    c2 = c * c
    if loss == "huber":
        big = s > c2
        # sqrt is evaluated on a safe value where unused, so its derivative cannot be inf.
        return jnp.where(big, 2.0 * c * jnp.sqrt(jnp.where(big, s, 1.0)) - c2, s)
    if loss == "cauchy":
        pos = c2 > 0
        return jnp.where(pos, c2 * jnp.log1p(s / jnp.where(pos, c2, 1.0)), 0.0)
    raise ValueError(f"loss must be one of {_LOSSES}; got {loss!r}")


# Jitted here so that eager calls compile once rather than op by op; under an outer
# jit, vmap or grad it is simply inlined.
@functools.partial(jax.jit, static_argnames="loss")
def _group_terms(rig, xy, groups, valid, loss, scale_px, points3d):
    """Per-group BPE ``(G,)`` and which groups count ``(G,)``."""
    M, P = xy.shape[0], xy.shape[1]
    if loss not in _LOSSES:
        raise ValueError(f"loss must be one of {_LOSSES}; got {loss!r}")
    if rig.K.shape != (M, 3, 3):
        raise ValueError(
            f"xy must have shape (M, P, 2) with M={rig.K.shape[0]} from the rig; got {xy.shape}"
        )
    G = groups.shape[0]
    if groups.shape != (G, M) or valid.shape != (G,):
        raise ValueError(
            f"groups must have shape (G, M={M}) and valid (G,); got {groups.shape} and {valid.shape}"
        )
    if points3d is not None and points3d.shape != (G, 3):
        raise ValueError(f"points3d must have shape (G={G}, 3); got {points3d.shape}")

    member = valid[:, None] & (groups >= 0) & (groups < P)  # (G, M)
    xy_g = gather_groups(groups, xy)  # (G, M, 2); out-of-range slots are clamped, then masked
    # Non-members read slot 0 of their view; zero them so that garbage cannot leak (a
    # where also passes a zero gradient, never 0 * NaN).
    xy_g = jnp.where(member[..., None], xy_g, 0.0)
    w = member.astype(xy.dtype)
    n = jnp.sum(w, axis=1)  # (G,)
    active = n >= 2

    if points3d is None:
        N, r, origin = dlt_blocks_views_last(rig, xy_g)  # (G, M, 3, 3), (G, M, 3), (3,)
        X, ok = solve_normal_3x3(jnp.einsum("gm,gmij->gij", w, N), jnp.einsum("gm,gmi->gi", w, r))
        X = X + origin[None, :]
        active = active & ok
    else:
        X = points3d
    X = jnp.where(active[:, None], X, 0.0)

    xy_hat, _ = project_views_last(rig, X)  # (G, M, 2)
    d = xy_hat - xy_g
    s = jnp.where(member, jnp.sum(d * d, axis=-1), 0.0)  # px², (G, M)
    rho = _rho(s, loss, jnp.asarray(scale_px, dtype=xy.dtype))
    total = jnp.sum(jnp.where(member, rho, 0.0), axis=1)
    per_group = jnp.where(active, total / jnp.maximum(n, 1.0), 0.0)
    return per_group, active


def group_bpe(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    groups: Int[Array, "G M"],
    valid: Bool[Array, " G"],
    *,
    loss: Loss = "l2",
    scale_px: Real[ArrayLike, ""] = 1.0,
    points3d: Float[Array, "G 3"] | None = None,
) -> Float[Array, " G"]:
    """Back-projection error of every group, ``(G,)`` (px² for ``"l2"``; docs/ALGORITHM.md §8).

    ``BPE(r) = mean over member views m of ρ(‖π_m(X_r) − x_m‖²)`` with ``ρ(s) = s``
    (``"l2"``), Huber ``ρ(s) = s`` if ``s ≤ c²`` else ``2c√s − c²``, or Cauchy
    ``ρ(s) = c² log(1 + s/c²)``, ``c = scale_px``; both robust kernels equal ``s`` for
    small residuals. Cheirality is not enforced (a point behind a camera still projects).

    Args:
        rig: ``M`` cameras.
        xy: ``(M, P, 2)`` detections (pixels); slots no group references may hold anything.
        groups: ``(G, M)`` int slot of each group's member in every view, -1 for none.
        valid: ``(G,)`` bool, row holds a group.
        loss: static kernel name, ``"l2"``, ``"huber"`` or ``"cauchy"``.
        scale_px: ``()`` kernel scale ``c`` (pixels, > 0; may be traced); unused for ``"l2"``.
        points3d: optional ``(G, 3)`` group points (scene units); by default each group's
            point is the multi-view DLT of its members.

    Returns:
        ``(G,)`` per-group BPE; 0 for rows that are invalid, have fewer than 2 members, or
        (when triangulating) whose DLT is undetermined (near-parallel rays).
    """
    expect_args(
        "group_bpe", rig=(rig, Rig), xy=(xy, ARRAY), groups=(groups, ARRAY), valid=(valid, ARRAY)
    )
    return _group_terms(rig, xy, groups, valid, loss=loss, scale_px=scale_px, points3d=points3d)[0]


def bpe(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    groups: Int[Array, "G M"],
    valid: Bool[Array, " G"],
    *,
    loss: Loss = "l2",
    scale_px: Real[ArrayLike, ""] = 1.0,
    points3d: Float[Array, "G 3"] | None = None,
) -> Float[Array, ""]:
    """Mean :func:`group_bpe` over the groups that count, ``()``: the scalar to differentiate.

    Arguments as :func:`group_bpe` (``xy (M, P, 2)``, ``groups (G, M)``, ``valid (G,)``,
    ``points3d (G, 3)``). Groups that are invalid, have fewer than 2 members or an
    undetermined DLT are left out of the mean; 0 when no group counts. Works under ``jit``
    and ``vmap`` (e.g. ``jax.vmap(bpe, in_axes=(None, 0, 0, 0))`` over scenes).
    """
    expect_args("bpe", rig=(rig, Rig), xy=(xy, ARRAY), groups=(groups, ARRAY), valid=(valid, ARRAY))
    per_group, active = _group_terms(
        rig, xy, groups, valid, loss=loss, scale_px=scale_px, points3d=points3d
    )
    count = jnp.sum(active.astype(per_group.dtype))
    return jnp.sum(per_group) / jnp.maximum(count, 1.0)
