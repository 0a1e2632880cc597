"""DLT triangulation, two-view and masked multi-view (ALGORITHM.md §9).

Each view contributes the rows ``x̂ P3 − P1`` and ``ŷ P3 − P2`` of the DLT in normalised
camera coordinates (``x̂ = K⁻¹ x``), with the world origin moved to the mean camera centre
so that every entry is O(1) in float32. With ``X = (x, y, z, 1)`` the least-squares problem
reduces to a 3×3 system ``(Σ_v N_v) X = −Σ_v r_v``, solved in closed form: a subset of
views is triangulated by summing its precomputed per-view blocks, and the derivative is
well defined wherever the system is (no SVD).

Tracks put the view axis first, ``xy (M, *S, 2)``, as detections ``(M, P, 2)``; the
``*_views_last`` variants take ``(*S, M, 2)``, the library's per-group tables.
"""

import jax.numpy as jnp

from .._expect import ARRAY, expect_args
from .._types import Array, Bool, Float, Int, lift
from ._camera import Rig
from ._checks import check_tracks
from ._distortion import as_lens, undistort_pixels
from ._homogeneous import homogeneous_from_points


def dlt_blocks(
    rig: Rig, xy: Float[Array, "M *S 2"]
) -> tuple[Float[Array, "M *S 3 3"], Float[Array, "M *S 3"], Float[Array, "3"]]:
    """Per-observation normal blocks ``N = AᵀA (M, *S, 3, 3)`` and ``r = Aᵀb (M, *S, 3)`` of
    the DLT rows of pixels ``xy (M, *S, 2)``.

    Returns ``(N, r, origin)``: solving ``(Σ N) X = −Σ r`` gives ``X + origin`` in world
    coordinates (scene units).
    """
    expect_args("dlt_blocks", rig=(rig, Rig), xy=(xy, ARRAY))
    N, r, origin = dlt_blocks_views_last(rig, jnp.moveaxis(xy, 0, -2))
    return jnp.moveaxis(N, -3, 0), jnp.moveaxis(r, -2, 0), origin


def dlt_blocks_views_last(
    rig: Rig, xy: Float[Array, "*S M 2"]
) -> tuple[Float[Array, "*S M 3 3"], Float[Array, "*S M 3"], Float[Array, "3"]]:
    """:func:`dlt_blocks` with the view axis last but one: ``xy (*S, M, 2)``."""
    origin = jnp.mean(rig.centers, axis=0)  # (3,)
    t_shift = rig.t + jnp.einsum("mij,j->mi", rig.R, origin)  # (M, 3)
    rays = jnp.einsum("mab,...mb->...ma", jnp.linalg.inv(rig.K), homogeneous_from_points(xy))
    # K is upper triangular, so rays[..., 2] = 1 / K[2, 2] is never 0.
    x_hat = rays[..., 0] / rays[..., 2]
    y_hat = rays[..., 1] / rays[..., 2]
    shape = x_hat.shape  # (*S, M)
    R = jnp.broadcast_to(rig.R, shape + (3, 3))
    t = jnp.broadcast_to(t_shift, shape + (3,))
    A0 = x_hat[..., None] * R[..., 2, :] - R[..., 0, :]  # (*S, M, 3)
    A1 = y_hat[..., None] * R[..., 2, :] - R[..., 1, :]
    b0 = x_hat * t[..., 2] - t[..., 0]  # (*S, M)
    b1 = y_hat * t[..., 2] - t[..., 1]
    N = A0[..., :, None] * A0[..., None, :] + A1[..., :, None] * A1[..., None, :]
    r = A0 * b0[..., None] + A1 * b1[..., None]
    return N, r, origin


def solve_normal_3x3(
    N: Float[Array, "*S 3 3"], r: Float[Array, "*S 3"], n_views: Int[Array, "*S"] | None = None
) -> tuple[Float[Array, "*S 3"], Bool[Array, "*S"]]:
    """Solve ``N X = −r`` for symmetric PSD ``N`` with the adjugate; ``ok`` is False (and
    X = 0) where ``N`` is near singular, or where ``n_views`` (the views that contributed,
    when known) is below 2.

    The conditioning test ``det N > c · trace(N)³`` is a bound on the ratio of the smallest
    to the largest eigenvalue (for ≥ 2 views ``det/trace³ ≈ λ_min/λ_max`` up to a factor
    below 30). ``c`` is ``max(1e-9, 16 ε)`` for the dtype's ε: in float32 the rounding of a
    rank-2 (single-view) ``N`` alone gives ``det/trace³`` near 1e-8, so a smaller ``c``
    would call one view determined. Two rays meeting at 0.5° pass in both precisions.
    """
    c0 = jnp.cross(N[..., 1, :], N[..., 2, :])
    c1 = jnp.cross(N[..., 2, :], N[..., 0, :])
    c2 = jnp.cross(N[..., 0, :], N[..., 1, :])
    det = jnp.sum(N[..., 0, :] * c0, axis=-1)
    trace = N[..., 0, 0] + N[..., 1, 1] + N[..., 2, 2]
    ok = det > conditioning_floor(N.dtype) * trace**3
    if n_views is not None:
        ok = ok & (n_views >= 2)
    inv_det = jnp.where(ok, 1.0 / jnp.where(ok, det, 1.0), 0.0)
    adj = jnp.stack([c0, c1, c2], axis=-1)  # symmetric N: adj(N) has these columns
    X = -jnp.einsum("...ij,...j->...i", adj, r) * inv_det[..., None]
    return X, ok


def conditioning_floor(dtype) -> float:
    """The smallest ``det N / trace(N)³`` that :func:`solve_normal_3x3` trusts in ``dtype``."""
    return max(1e-9, 16.0 * float(jnp.finfo(dtype).eps))


def triangulate(
    rig: Rig,
    xy: Float[Array, "M *S 2"],
    mask: Bool[Array, "M *S"] | None,
    *,
    weights: Float[Array, "M *S"] | None = None,
    dist=None,
) -> tuple[Float[Array, "*S 3"], Bool[Array, "*S"]]:
    """Multi-view DLT of any batch of tracks, without association; jit/vmap friendly.

    Args:
        rig: ``M`` cameras.
        xy: ``(M, *S, 2)`` pixels of each track in every view (the view axis first, as
            detections ``(M, P, 2)``); masked entries may hold anything (NaN, ±inf, huge
            values): they are replaced before any arithmetic, so they change neither the
            point nor ``ok`` nor a gradient.
        mask: ``(M, *S)`` bool, the views that observe the track; ``None`` (pass it
            explicitly: ``triangulate(rig, xy, None)``): the views whose two coordinates
            are finite (NaN marks a missing view, as in anipose and DeepLabCut tracks).
        weights: optional ``(M, *S)`` non-negative weight of each view's equations (e.g.
            detector confidence): the normal equations become ``Σ_v w_v N_v``. A view with
            weight 0 (or a non-finite weight) counts as unobserved.
        dist: the lens of every view (``(M, 5)`` OpenCV coefficients or a
            :class:`cdog_jax.geometry.Fisheye`): ``xy`` are then recorded (distorted)
            pixels, undistorted first. ``None``: ``xy`` are ideal pinhole pixels.

    Returns:
        ``points (*S, 3)`` (scene units, 0 where undetermined) and ``ok (*S,)``: the point is
        determined, i.e. ≥ 2 views count and the normal equations are well conditioned (see
        :func:`solve_normal_3x3`). ``ok`` says nothing about cheirality or parallax: see
        :func:`cdog_jax.geometry.in_front` and the validity gate's parallax (`refine/_validity.py`).
    """
    if mask is None:
        mask = jnp.all(jnp.isfinite(jnp.asarray(xy)), axis=-1)
    check_tracks(rig, xy, mask, weights, "triangulate")
    if dist is not None:
        xy = jnp.where(mask[..., None], xy, 0.0)
        xy = undistort_pixels(
            rig.K, as_lens(dist, xy.dtype), xy.reshape(xy.shape[0], -1, 2)
        ).reshape(xy.shape)
    if weights is not None:
        weights = jnp.moveaxis(weights, 0, -1)
    return triangulate_views_last(
        rig, jnp.moveaxis(xy, 0, -2), jnp.moveaxis(mask, 0, -1), weights=weights
    )


def triangulate_views_last(
    rig: Rig,
    xy: Float[Array, "*S M 2"],
    mask: Bool[Array, "*S M"],
    *,
    weights: Float[Array, "*S M"] | None = None,
) -> tuple[Float[Array, "*S 3"], Bool[Array, "*S"]]:
    """:func:`triangulate` of tracks laid out view axis last: ``xy (*S, M, 2)``,
    ``mask (*S, M)``, ``weights (*S, M)`` (the library's per-group tables)."""
    w = mask.astype(xy.dtype)
    if weights is not None:
        w = jnp.where(mask & jnp.isfinite(weights) & (weights > 0), weights.astype(xy.dtype), 0.0)
    counts = w > 0
    xy = jnp.where(counts[..., None], xy, 0.0)  # neutral before any arithmetic (and gradient)
    N, r, origin = dlt_blocks_views_last(rig, xy)
    X, ok = solve_normal_3x3(
        jnp.einsum("...m,...mij->...ij", w, N),
        jnp.einsum("...m,...mi->...i", w, r),
        jnp.sum(counts, axis=-1, dtype=jnp.int32),
    )
    return jnp.where(ok[..., None], X + lift(origin, X.ndim), 0.0), ok


def triangulate_pairs(
    N: Float[Array, "M 3 3"], r: Float[Array, "M 3"], origin: Float[Array, "3"]
) -> tuple[Float[Array, "M M 3"], Bool[Array, "M M"]]:
    """Two-view DLT for every pair of one track's views from its per-view blocks
    ``N (M, 3, 3)``, ``r (M, 3)``: ``X (M, M, 3)`` with ``X[a, b]`` from views a and b, and
    ``ok (M, M)`` (False on the diagonal and for near-parallel rays)."""
    expect_args("triangulate_pairs", N=(N, ARRAY), r=(r, ARRAY), origin=(origin, ARRAY))
    X, ok = solve_normal_3x3(N[:, None] + N[None, :], r[:, None] + r[None, :])
    ok = ok & ~jnp.eye(N.shape[0], dtype=bool)
    return X + lift(origin, X.ndim), ok
