"""OpenCV lens distortion: agreement with the formula, inversion, gradients, general K."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cdog_jax.geometry import distort_pixels, undistort_pixels
from cdog_jax.geometry._distortion import _check

W, H = 640, 480
# Two views on a 640×480, f ≈ 500 camera: strong barrel distortion and a mild one.
DIST = np.array(
    [
        [-0.3, 0.1, 1e-3, 1e-3, 0.0],
        [-0.05, 0.01, 2e-4, -1e-4, 1e-3],
    ]
)
K_NP = np.array(
    [
        [[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]],
        [[505.0, 0.8, 316.0], [0.0, 498.0, 243.0], [0.0, 0.0, 1.0]],
    ]
)


# One jitted function per operation and, where possible, one shape (2, 99, 2): compilation
# dominates the run time of these tests.
distort = jax.jit(distort_pixels)
undistort = jax.jit(undistort_pixels)
grad_undistort = jax.jit(
    jax.grad(lambda K, d, p: jnp.sum(undistort_pixels(K, d, p) ** 2), argnums=(0, 1, 2))
)


def _image_grid(nx=11, ny=9):
    """``(2, nx*ny, 2)`` pixels covering the whole image, borders included, in both views."""
    gx, gy = np.meshgrid(np.linspace(0, W, nx), np.linspace(0, H, ny))
    pts = np.stack([gx.ravel(), gy.ravel()], -1)
    return np.stack([pts, pts])


def _opencv_distort_np(K, dist, xy):
    """OpenCV's projection model written out in NumPy (float64): K⁻¹, distort, K."""
    out = np.empty_like(xy)
    for m in range(K.shape[0]):
        k1, k2, p1, p2, k3 = dist[m]
        h = np.linalg.inv(K[m]) @ np.concatenate([xy[m], np.ones((xy.shape[1], 1))], 1).T
        x, y = h[0] / h[2], h[1] / h[2]
        r2 = x**2 + y**2
        radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x**2)
        yd = y * radial + p1 * (r2 + 2 * y**2) + 2 * p2 * x * y
        hd = K[m] @ np.stack([xd, yd, np.ones_like(xd)])
        out[m] = (hd[:2] / hd[2]).T
    return out


def test_round_trip_over_the_image_float32():
    K, dist, xy = (jnp.asarray(a, jnp.float32) for a in (K_NP, DIST, _image_grid()))
    distorted = distort(K, dist, xy)
    # Sanity: the strong view really distorts (corners move by tens of pixels).
    assert float(jnp.abs(distorted - xy)[0].max()) > 30.0
    back = undistort(K, dist, distorted)
    err = np.abs(np.asarray(back) - np.asarray(xy)).max(axis=(1, 2))
    assert err[0] < 1e-3 and err[1] < 1e-3, err


def test_distort_matches_numpy_opencv_formula():
    rng = np.random.default_rng(0)
    xy = rng.uniform([0, 0], [W, H], size=_image_grid().shape)
    expected = _opencv_distort_np(K_NP, DIST, xy)
    got = distort(*(jnp.asarray(a, jnp.float32) for a in (K_NP, DIST, xy)))
    np.testing.assert_allclose(np.asarray(got), expected, atol=1e-3)


def test_zero_distortion_is_exactly_the_identity():
    K, xy = jnp.asarray(K_NP, jnp.float32), jnp.asarray(_image_grid(), jnp.float32)
    zero = jnp.zeros((2, 5), jnp.float32)
    np.testing.assert_array_equal(np.asarray(distort(K, zero, xy)), np.asarray(xy))
    np.testing.assert_array_equal(np.asarray(undistort(K, zero, xy)), np.asarray(xy))


def test_negative_K22_gives_the_same_pixels():
    K, dist, xy = (jnp.asarray(a, jnp.float32) for a in (K_NP, DIST, _image_grid()))
    K_neg = K * jnp.asarray([-1.0, 1.0], jnp.float32)[:, None, None]  # view 0: K[2,2] = -1
    distorted = distort(K, dist, xy)
    np.testing.assert_allclose(
        np.asarray(distort(K_neg, dist, xy)), np.asarray(distorted), atol=1e-3
    )
    np.testing.assert_allclose(
        np.asarray(undistort(K_neg, dist, distorted)), np.asarray(xy), atol=1e-3
    )


def test_padded_garbage_and_zero_distortion_give_finite_values_and_gradients():
    K = jnp.asarray(K_NP, jnp.float32)
    xy = _image_grid()
    xy[:, :3] = 0.0  # padded slots
    xy[0, 3], xy[1, 3] = (1e6, -1e6), (3e4, 2e4)  # garbage far outside the image
    xy = jnp.asarray(xy, jnp.float32)
    for dist in (jnp.asarray(DIST, jnp.float32), jnp.zeros((2, 5), jnp.float32)):
        assert np.isfinite(np.asarray(undistort(K, dist, xy))).all()
        assert all(np.isfinite(np.asarray(g)).all() for g in grad_undistort(K, dist, xy))


def test_gradients_match_finite_differences_float64():
    with jax.enable_x64(True):
        rng = np.random.default_rng(1)
        K = jnp.asarray(K_NP * np.array([1.0, -1.0])[:, None, None])  # view 1: K[2,2] = -1
        dist = jnp.asarray(DIST)
        xy = jnp.asarray(rng.uniform([0, 0], [W, H], size=(2, 3, 2)))
        weights = jnp.asarray(rng.normal(size=(2, 3, 2)))

        def loss(K, dist, xy):
            return jnp.sum(weights * undistort_pixels(K, dist, xy))

        value_and_grad = jax.jit(jax.value_and_grad(loss, argnums=(0, 1, 2)))  # one compilation
        _, grads = value_and_grad(K, dist, xy)
        args = [K, dist, xy]
        for i, g in enumerate(grads):
            v = jnp.asarray(rng.normal(size=args[i].shape))
            if i == 0:
                v = jnp.triu(v)  # K stays upper-triangular
            # Small steps: K[2,2] = ±1 sits beside entries of 500 px.
            v = v / jnp.linalg.norm(v) * (1e-6 * float(jnp.abs(args[i]).max()))
            plus, minus = list(args), list(args)
            plus[i], minus[i] = args[i] + v, args[i] - v
            fd = (value_and_grad(*plus)[0] - value_and_grad(*minus)[0]) / 2
            np.testing.assert_allclose(float(jnp.sum(g * v)), float(fd), rtol=1e-6, atol=1e-10)


def test_vmap_over_scenes_equals_a_loop():
    B = 3
    K = jnp.asarray(K_NP, jnp.float32)
    dist = (
        jnp.asarray(DIST, jnp.float32)[None]
        * jnp.asarray([0.5, 1.0, 1.5], jnp.float32)[:, None, None]
    )  # (B, 2, 5)
    xy = jnp.broadcast_to(jnp.asarray(_image_grid(), jnp.float32), (B,) + _image_grid().shape)
    batched = jax.jit(jax.vmap(undistort_pixels, in_axes=(None, 0, 0)))(K, dist, xy)
    for b in range(B):
        np.testing.assert_allclose(
            np.asarray(batched[b]), np.asarray(undistort(K, dist[b], xy[b])), atol=1e-4
        )
    back = jax.jit(jax.vmap(distort_pixels, in_axes=(None, 0, 0)))(K, dist, batched)
    np.testing.assert_allclose(np.asarray(back), np.asarray(xy), atol=1e-3)


def test_bad_shapes_raise():
    K, xy = jnp.asarray(K_NP, jnp.float32), jnp.zeros((2, 3, 2), jnp.float32)
    # Under the test suite's jaxtyping hook a shape error may surface as a TypeCheckError first.
    with pytest.raises((ValueError, TypeError), match="dist"):
        distort_pixels(K, jnp.zeros((2, 4), jnp.float32), xy)
    with pytest.raises((ValueError, TypeError), match="xy"):
        undistort_pixels(K, jnp.zeros((2, 5), jnp.float32), jnp.zeros((3, 3, 2), jnp.float32))
    # The eager checks themselves (what users get without the hook).
    with pytest.raises(ValueError, match=r"dist must have shape \(M, 5\)"):
        _check(K, jnp.zeros((2, 4), jnp.float32), xy)
    with pytest.raises(ValueError, match=r"xy must have shape \(M, P, 2\) with M=2"):
        _check(K, jnp.zeros((2, 5), jnp.float32), jnp.zeros((3, 3, 2), jnp.float32))
