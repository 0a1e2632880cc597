"""Projection of world points into every view, and reprojection errors (pixels).

Per-view arrays put the view axis first: ``project`` returns ``(M, *S, 2)``, as detections
``(M, P, 2)`` and tracks ``(M, N, 2)`` are laid out. The ``*_views_last`` variants return
``(*S, M, …)`` for the library's per-group tables ``(G, M, …)``.
"""

import jax.numpy as jnp
import numpy as np

from .._expect import ARRAY, expect_args
from .._types import Array, Bool, Float
from ._camera import Rig, affine_per_view
from ._distortion import as_lens, distort_pixels
from ._homogeneous import points_from_homogeneous


def project(
    rig: Rig, X_world: Float[Array, "*S 3"], *, dist=None
) -> tuple[Float[Array, "M *S 2"], Bool[Array, "M *S"]]:
    """Pixels of world points in every view, ``(M, *S, 2)``, and a flag ``(M, *S)`` that the
    point is in front of the camera (``X_cam[2] > 0``) and projects to a finite pixel.

    ``dist``: the lens of every view (``(M, 5)`` OpenCV coefficients or a
    :class:`cdog_jax.geometry.Fisheye`); the pixels are then distorted, as a real camera
    records them. ``None``: ideal pinhole pixels.
    """
    expect_args("project", rig=(rig, Rig), X_world=(X_world, ARRAY))
    if np.ndim(X_world) < 1 or np.shape(X_world)[-1] != 3:
        raise ValueError(
            f"project: X_world must have shape (..., 3), world points; got {np.shape(X_world)}"
        )
    xy, ok = project_views_last(rig, X_world)
    xy, ok = jnp.moveaxis(xy, -2, 0), jnp.moveaxis(ok, -1, 0)
    if dist is not None:
        xy = distort_pixels(rig.K, as_lens(dist, xy.dtype), xy.reshape(xy.shape[0], -1, 2)).reshape(
            xy.shape
        )
    return xy, ok


def project_views_last(
    rig: Rig, X_world: Float[Array, "*S 3"]
) -> tuple[Float[Array, "*S M 2"], Bool[Array, "*S M"]]:
    """:func:`project` with the view axis last but one: ``(*S, M, 2)`` and ``(*S, M)``."""
    proj = rig.proj  # (M, 3, 4)
    h = affine_per_view(proj[:, :, :3], proj[:, :, 3], X_world)  # (*S, M, 3)
    depth = affine_per_view(rig.R[:, 2:3, :], rig.t[:, 2:3], X_world)[..., 0]  # X_cam z, (*S, M)
    xy, ok = points_from_homogeneous(h)
    return xy, ok & (depth > 0)


def pixel_distances(
    pix: Float[Array, "*S M 2"], xy: Float[Array, "M P 2"]
) -> Float[Array, "*S M P"]:
    """Pixel distance ``(*S, M, P)`` from a pixel per view ``pix (*S, M, 2)`` to every slot of
    that view's detections ``xy (M, P, 2)``. With x and y apart and no gather, XLA vectorises
    the table along the slots (a trailing axis of length 2 would keep it from doing so)."""
    lead = (None,) * (pix.ndim - 2)  # the axes of S
    dx = pix[..., None, 0] - xy[lead + (..., 0)]
    dy = pix[..., None, 1] - xy[lead + (..., 1)]
    return jnp.sqrt(dx * dx + dy * dy)


def distances_to_detections(
    rig: Rig, X_world: Float[Array, "G 3"], xy: Float[Array, "M P 2"]
) -> tuple[Float[Array, "G M P"], Bool[Array, "G M"]]:
    """Pixel distance ``(G, M, P)`` from every point ``X (G, 3)`` projected into each view to
    every slot of that view's detections ``xy (M, P, 2)`` (mask them as needed), and whether
    each point is in front of each camera ``(G, M)``."""
    pix, in_front = project_views_last(rig, X_world)  # (G, M, 2), (G, M)
    return pixel_distances(pix, xy), in_front


def reprojection_errors(
    rig: Rig, X_world: Float[Array, "*S 3"], xy: Float[Array, "M *S 2"]
) -> Float[Array, "M *S"]:
    """Pixel distance ``‖π_m(X) − x_m‖`` in every view, ``(M, *S)``, of points ``X (*S, 3)``
    and their pixels ``xy (M, *S, 2)``; finite even where the point projects badly (such
    entries are meaningful only where the caller masks them)."""
    expect_args("reprojection_errors", rig=(rig, Rig), X_world=(X_world, ARRAY), xy=(xy, ARRAY))
    return jnp.moveaxis(
        reprojection_errors_views_last(rig, X_world, jnp.moveaxis(xy, 0, -2)), -1, 0
    )


def reprojection_errors_views_last(
    rig: Rig, X_world: Float[Array, "*S 3"], xy: Float[Array, "*S M 2"]
) -> Float[Array, "*S M"]:
    """:func:`reprojection_errors` with the view axis last (``xy (*S, M, 2)`` → ``(*S, M)``)."""
    xy_hat, _ = project_views_last(rig, X_world)
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
    err = reprojection_errors_views_last(rig, X, xy_g)  # (G, M)
    w = member.astype(err.dtype)
    n = jnp.maximum(jnp.sum(w, axis=1), 1.0)
    return jnp.sum(w * err * err, axis=1) / n, jnp.sum(w * err, axis=1) / n
