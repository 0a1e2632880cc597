"""What happens after any method has associated one scene of real data: confidence-weighted
triangulation, a minimum number of views per group, and the validity gate again. A pure,
traced function (jit/vmap it), used by :func:`cdog_jax.associate` and
:func:`cdog_jax.associate_batch`.
"""

from __future__ import annotations

import jax.numpy as jnp


from ._result import Association, association_from_groups
from ._types import Array, Float, Int
from .geometry._camera import Rig
from .geometry._projection import group_errors
from .geometry._triangulate import triangulate_views_last
from .graph._groups import gather_groups
from .refine._validity import validity_gate


def finish_groups(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    result: Association,
    weights: Float[Array, "M P"] | None,
    min_views: Int[Array, ""],
    th: tuple,
) -> Association:
    """``result`` with groups of fewer than ``min_views`` views dropped (their detections
    become unassigned) and, when ``weights (M, P)`` is given (e.g. detector confidence, ≥ 0),
    every point re-triangulated by DLT with each member's equation scaled by its weight.

    BPE and the mean error stay the plain (unweighted) means over members;
    ``xy`` are the pixels the association used (undistorted). The groups then pass the
    validity gate again (:func:`cdog_jax.refine.validity_gate`, with ``th.max_err_frac``,
    ``th.min_parallax_deg`` and the result's τ): a member of weight 0 does not count as a
    view, and a re-weighted point must still lie in front of its cameras with parallax and
    bounded errors. Groups are compacted to the front again and the labels rebuilt, as
    :func:`cdog_jax.associate` returns them.
    """
    P = xy.shape[1]
    keep = result.valid & (result.n_views >= min_views)
    groups = jnp.where(keep[:, None], result.groups, -1)
    member = keep[:, None] & (groups >= 0)  # (G, M)
    xy_g = gather_groups(groups, xy)  # (G, M, 2)
    X = result.points3d
    w_g = None
    if weights is not None:
        w_g = jnp.where(member, gather_groups(groups, weights), 0.0)
        X_w, ok = triangulate_views_last(rig, xy_g, member, weights=w_g)
        X = jnp.where(ok[:, None], X_w, X)  # fewer than 2 weighted views: the gate dissolves it
    member, keep, X = validity_gate(rig, xy_g, member, X, result.tau_px, th.max_err_frac, th.min_parallax_deg, weights=w_g)
    keep = keep & (jnp.sum(member, axis=1, dtype=jnp.int32) >= min_views)  # detaching may leave fewer
    member = member & keep[:, None]
    groups = jnp.where(member, groups, -1)
    bpe, err_px = group_errors(rig, X, xy_g, member)
    return association_from_groups(groups, keep, member, X, bpe, err_px, P, result.sigma_px, result.tau_px, result.status)
