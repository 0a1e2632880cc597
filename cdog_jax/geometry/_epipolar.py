"""Fundamental matrices of all view pairs and the epipolar distance table (paper Alg. 1)."""

import jax.numpy as jnp

from .._expect import ARRAY, expect_args
from .._types import Array, Bool, Float
from ._camera import Rig
from ._homogeneous import homogeneous_from_points


def skew(v: Float[Array, "*S 3"]) -> Float[Array, "*S 3 3"]:
    """Cross-product matrix ``[v]_x`` with ``[v]_x w = v × w``."""
    z = jnp.zeros_like(v[..., 0])
    rows = (
        jnp.stack([z, -v[..., 2], v[..., 1]], -1),
        jnp.stack([v[..., 2], z, -v[..., 0]], -1),
        jnp.stack([-v[..., 1], v[..., 0], z], -1),
    )
    return jnp.stack(rows, -2)


def essential_from_rig(rig: Rig) -> Float[Array, "M M 3 3"]:
    """``E (M, M, 3, 3)``, ``E[m, n] = [t_rel]_x R_rel`` with ``R_rel = R_n R_mᵀ``, ``t_rel = t_n − R_rel t_m``
    scaled to unit length: ``x̂_nᵀ E x̂_m = 0`` for normalised rays ``x̂ = K⁻¹ x``."""
    expect_args("essential_from_rig", rig=(rig, Rig))
    R_rel = jnp.einsum("nij,mkj->mnik", rig.R, rig.R)  # R_n R_mᵀ, (M, M, 3, 3)
    t_rel = rig.t[None, :, :] - jnp.einsum("mnij,mj->mni", R_rel, rig.t)  # (M, M, 3)
    t_norm = jnp.sqrt(jnp.sum(t_rel * t_rel, axis=-1, keepdims=True))
    M = rig.K.shape[0]
    # The diagonal is zero up to round-off only; zero it exactly (no pair of a view with itself).
    ok = (t_norm > 0) & ~jnp.eye(M, dtype=bool)[..., None]
    t_unit = jnp.where(ok, t_rel / jnp.where(ok, t_norm, 1.0), 0.0)
    return jnp.einsum("mnij,mnjk->mnik", skew(t_unit), R_rel)


def fundamental_from_rig(rig: Rig) -> Float[Array, "M M 3 3"]:
    """``F[m, n]`` with ``x_nᵀ F[m, n] x_m = 0`` for pixels of one point in views m and n.

    ``F = K_n^{-T} [t_rel]_x R_rel K_m^{-1}`` scaled to unit Frobenius norm (0 on the diagonal
    ``m == n``). General K: no assumption on the sign of ``K[2,2]``.
    """
    expect_args("fundamental_from_rig", rig=(rig, Rig))
    K_inv = jnp.linalg.inv(rig.K)  # (M, 3, 3)
    F = jnp.einsum("nji,mnjk,mkl->mnil", K_inv, essential_from_rig(rig), K_inv)
    norm = jnp.sqrt(jnp.sum(F * F, axis=(-2, -1), keepdims=True))
    ok = norm > 0
    return jnp.where(ok, F / jnp.where(ok, norm, 1.0), 0.0)


def epipolar_distances(
    rig: Rig, xy: Float[Array, "M P 2"], mask: Bool[Array, "M P"]
) -> Float[Array, "M P M P"]:
    """``d[m, i, n, j]``: distance (pixels) in image n from ``xy[n, j]`` to the epipolar line
    ``F[m, n] x_(m,i)``. ``+inf`` where ``m == n``, where a slot is padding, or where the line
    is degenerate (``x_(m,i)`` at the epipole).

    Computed in normalised coordinates (``l̂ = E x̂_m``, numerator ``l̂ · x̂_n``) so that every
    term is O(1) in float32; the pixel line is ``l = K_n^{-T} l̂``, whose first two entries
    give the pixel-unit normaliser.
    """
    expect_args("epipolar_distances", rig=(rig, Rig), xy=(xy, ARRAY), mask=(mask, ARRAY))
    M, P = mask.shape
    K_inv = jnp.linalg.inv(rig.K)
    rays = jnp.einsum("mab,mib->mia", K_inv, homogeneous_from_points(xy))  # (M, P, 3)
    lines_hat = jnp.einsum("mnab,mib->mina", essential_from_rig(rig), rays)  # (M, P, M, 3)
    lines_px = jnp.einsum("nba,minb->mina", K_inv, lines_hat)  # K_n^{-T} l̂, (M, P, M, 3)
    line_norm_sq = lines_px[..., 0] ** 2 + lines_px[..., 1] ** 2  # (M, P, M)
    ok_line = line_norm_sq > jnp.finfo(xy.dtype).tiny
    inv_norm = jnp.where(ok_line, 1.0 / jnp.sqrt(jnp.where(ok_line, line_norm_sq, 1.0)), 0.0)
    lines = lines_hat * inv_norm[..., None]  # scaled so that l · x̂_n is in pixels
    # Three broadcast products rather than an einsum: XLA fuses them with the masking
    # below into one pass over the (M, P, M, P) table (twice as fast on CPU).
    r = rays[None, None]  # (1, 1, M, P, 3)
    d = jnp.abs(sum(lines[..., k, None] * r[..., k] for k in range(3)))
    views = jnp.arange(M, dtype=jnp.int32)
    ok = (
        mask[:, :, None, None]
        & mask[None, None, :, :]
        & ok_line[..., None]
        & (views[:, None] != views[None, :])[:, None, :, None]
    )
    return jnp.where(ok, d, jnp.inf)
