"""What happens around the association of one scene when the input is real data: lens
undistortion before it, and after it confidence-weighted triangulation and a minimum
number of views per group. Pure, traced functions (jit/vmap them), used by
:func:`cdog_jax.associate` and :func:`cdog_jax.associate_batch`.
"""

from __future__ import annotations

import jax.numpy as jnp

from ._config import Thresholds
from ._result import Association
from ._types import Array, Bool, Float, Int
from .geometry._camera import Rig
from .geometry._distortion import Fisheye, undistort_pixels
from .geometry._projection import group_errors
from .geometry._triangulate import triangulate_views_last
from .graph._groups import compact_groups, gather_groups, labels_from_groups
from .refine._validity import validity_gate


def undistorted(
    rig: Rig, xy: Float[Array, "M P 2"], mask: Bool[Array, "M P"], dist: Float[Array, "M 5"] | Fisheye
) -> Float[Array, "M P 2"]:
    """Detections ``xy (M, P, 2)`` (pixels, as the lens saw them) mapped to the ideal pinhole
    pixels of ``rig`` through OpenCV distortion ``dist (M, 5)`` or a :class:`Fisheye`;
    padding stays 0."""
    return jnp.where(mask[..., None], undistort_pixels(rig.K, dist, jnp.where(mask[..., None], xy, 0.0)), 0.0)


def finish_groups(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    result: Association,
    weights: Float[Array, "M P"] | None,
    min_views: Int[Array, ""],
    th: Thresholds,
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
    groups, keep, order = compact_groups(groups, keep)
    return Association(
        labels=labels_from_groups(groups, keep, P),
        groups=groups,
        valid=keep,
        points3d=jnp.where(keep[:, None], X[order], 0.0),
        bpe=jnp.where(keep, bpe[order], 0.0),
        err_px=jnp.where(keep, err_px[order], 0.0),
        n_views=jnp.sum(groups >= 0, dtype=jnp.int32, axis=1),
        num_groups=jnp.sum(keep, dtype=jnp.int32),
        sigma_px=result.sigma_px,
        tau_px=result.tau_px,
        status=result.status,
    )
