"""Projection of world points into every view, and reprojection errors (pixels)."""

import jax.numpy as jnp

from .._expect import ARRAY, expect_args
from .._types import Array, Bool, Float
from ._camera import Rig, affine_per_view
from ._homogeneous import points_from_homogeneous


def project(rig: Rig, X_world: Float[Array, "*S 3"]) -> tuple[Float[Array, "*S M 2"], Bool[Array, "*S M"]]:
    """Pixels of world points in every view, ``(*S, M, 2)``, and a flag that the point is in
    front of the camera (``X_cam[2] > 0``) and projects to a finite pixel."""
    expect_args("project", rig=(rig, Rig), X_world=(X_world, ARRAY))
    proj = jnp.einsum("mij,mjk->mik", rig.K, jnp.concatenate([rig.R, rig.t[:, :, None]], axis=-1))  # (M, 3, 4)
    h = affine_per_view(proj[:, :, :3], proj[:, :, 3], X_world)  # (*S, M, 3)
    depth = affine_per_view(rig.R[:, 2:3, :], rig.t[:, 2:3], X_world)[..., 0]  # X_cam z, (*S, M)
    xy, ok = points_from_homogeneous(h)
    return xy, ok & (depth > 0)


def reprojection_errors(
    rig: Rig, X_world: Float[Array, "*S 3"], xy: Float[Array, "*S M 2"]
) -> Float[Array, "*S M"]:
    """Pixel distance ``‖π_m(X) − x_m‖`` in every view (``(*S, M)``); finite even where the
    point projects badly (such entries are meaningful only where the caller masks them)."""
    expect_args("reprojection_errors", rig=(rig, Rig), X_world=(X_world, ARRAY), xy=(xy, ARRAY))
    xy_hat, _ = project(rig, X_world)
    diff = xy_hat - xy
    sq = jnp.sum(diff * diff, axis=-1)
    # sqrt has an infinite derivative at 0: exact reprojections are common (σ = 0).
    pos = sq > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, sq, 1.0)), 0.0)


def group_errors(
    rig: Rig, X: Float[Array, "G 3"], xy_g: Float[Array, "G M 2"], member: Bool[Array, "G M"]
) -> tuple[Float[Array, " G"], Float[Array, " G"]]:
    """Per group, the BPE ``mean_m ‖π_m(X) − x_m‖²`` (px²) and the mean reprojection distance
    (px) over the member views ``member (G, M)``; 0 for a group without members."""
    err = reprojection_errors(rig, X, xy_g)  # (G, M)
    w = member.astype(err.dtype)
    n = jnp.maximum(jnp.sum(w, axis=1), 1.0)
    return jnp.sum(w * err * err, axis=1) / n, jnp.sum(w * err, axis=1) / n
