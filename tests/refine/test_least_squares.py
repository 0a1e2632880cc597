"""Refinement of each group's point by Levenberg–Marquardt (refine/_least_squares.py):
float32 points refine alike with 64-bit JAX on or off (optimistix's damping then takes
float64, which a float32 problem would not match)."""

import jax
import jax.numpy as jnp
import numpy as np
from helpers import project_np, ring_rig, x64

from cdog_jax.refine._least_squares import refine_points


def _groups():
    """Three points seen by four views, 0.5 px of noise, each started 2 cm off."""
    rng = np.random.default_rng(0)
    rig = ring_rig(4)
    X = rng.uniform(-0.5, 0.5, (3, 3))
    xy, _ = project_np(rig, X)  # (M, G, 2)
    xy_g = np.transpose(xy, (1, 0, 2)) + rng.normal(0.0, 0.5, (3, 4, 2))
    member = np.ones((3, 4), bool)
    member[0, 3] = False
    X0 = X + rng.normal(0.0, 0.02, X.shape)
    as32 = lambda a: jnp.asarray(a, jnp.float32)  # noqa: E731
    return rig, as32(X0), as32(xy_g), jnp.asarray(member), X


def test_float32_points_refine_alike_with_64_bit_jax_on_or_off():
    rig, X0, xy_g, member, X = _groups()
    refine = jax.jit(refine_points, static_argnums=4)
    X32, capped32 = refine(rig, X0, xy_g, member, 20)
    with x64(True):
        X64, capped64 = refine(rig, X0, xy_g, member, 20)
        assert X64.dtype == jnp.float32
    assert X32.dtype == jnp.float32
    assert not bool(capped32) and not bool(capped64)

    # Both lower every group's reprojection error well below the start's.
    def squared_error(points):
        xy, _ = project_np(rig, np.asarray(points, np.float64))
        d = np.transpose(xy, (1, 0, 2)) - np.asarray(xy_g, np.float64)
        return np.sum(np.where(np.asarray(member)[..., None], d * d, 0.0), axis=(1, 2))

    start = squared_error(X0)
    for refined in (X32, X64):
        assert np.all(squared_error(refined) < start / 4)
    np.testing.assert_allclose(np.asarray(X64), np.asarray(X32), atol=1e-4)
