"""OpenCV's fisheye model (``cv2.fisheye``): agreement with the published formula (and with
OpenCV when installed), inversion, gradients, general K."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import x64

from cdog_jax.geometry import Fisheye, distort_pixels, undistort_pixels

# A wide lens (f = 300 px on 640×480: corners at θ ≈ 53°) and a mild one with skew.
COEFFS = np.array([[0.08, -0.02, 0.004, -0.0008], [-0.01, 0.003, 0.0, 0.0]])
K_NP = np.array(
    [
        [[300.0, 0.0, 320.0], [0.0, 305.0, 240.0], [0.0, 0.0, 1.0]],
        [[420.0, 0.9, 316.0], [0.0, 418.0, 243.0], [0.0, 0.0, 1.0]],
    ]
)
distort = jax.jit(distort_pixels)
undistort = jax.jit(undistort_pixels)


def _grid():
    gx, gy = np.meshgrid(np.linspace(0, 640, 9), np.linspace(0, 480, 7))
    pts = np.stack([gx.ravel(), gy.ravel()], -1)
    return np.stack([pts, pts])  # (2, 63, 2)


def _fisheye_np(K, k, xy):
    """OpenCV's documented fisheye projection of ideal pixels, transcribed in NumPy float64."""
    y = (xy[:, 1] - K[1, 2]) / K[1, 1]
    x = (xy[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
    r = np.hypot(x, y)
    theta = np.arctan(r)
    theta_d = theta * (1 + k[0] * theta**2 + k[1] * theta**4 + k[2] * theta**6 + k[3] * theta**8)
    scale = np.where(r > 0, theta_d / np.where(r > 0, r, 1.0), 1.0)
    xd, yd = x * scale, y * scale
    return np.stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]], -1)


def test_distortion_is_the_published_formula_and_inverts():
    xy = _grid()
    with x64(True):
        got = np.asarray(distort(jnp.asarray(K_NP), Fisheye(jnp.asarray(COEFFS)), jnp.asarray(xy)))
        back = np.asarray(
            undistort(jnp.asarray(K_NP), Fisheye(jnp.asarray(COEFFS)), jnp.asarray(got))
        )
    expected = np.stack([_fisheye_np(K_NP[m], COEFFS[m], xy[m]) for m in range(2)])
    np.testing.assert_allclose(got, expected, atol=1e-9)
    assert np.abs(got - xy).max() > 20  # a real lens: tens of pixels at the corners
    np.testing.assert_allclose(back, xy, atol=1e-8)
    # The centre stays put (θ_d / r → 1 there).
    centre = K_NP[:, None, :2, 2]
    np.testing.assert_array_equal(
        np.asarray(distort(jnp.asarray(K_NP), Fisheye(jnp.asarray(COEFFS)), jnp.asarray(centre))),
        centre,
    )


def test_float32_round_trip_and_finite_gradients():
    xy = jnp.asarray(_grid(), jnp.float32)
    K, lens = jnp.asarray(K_NP, jnp.float32), Fisheye(jnp.asarray(COEFFS, jnp.float32))
    back = undistort(K, lens, distort(K, lens, xy))
    assert float(jnp.abs(back - xy).max()) < 2e-3

    def loss(coeffs, xy):
        return jnp.sum(undistort_pixels(K, Fisheye(coeffs), xy) ** 2)

    g_coeffs, g_xy = jax.jit(jax.grad(loss, argnums=(0, 1)))(lens.coeffs, xy)
    assert np.isfinite(np.asarray(g_coeffs)).all() and np.isfinite(np.asarray(g_xy)).all()


def test_undistortion_gradient_is_the_implicit_derivative():
    xy = _grid()[:, 10:13]
    with x64(True):
        K = jnp.asarray(K_NP)

        @jax.jit
        def f(c):
            return undistort_pixels(K, Fisheye(c), jnp.asarray(xy))

        c0 = jnp.asarray(COEFFS)
        J = np.asarray(jax.jit(jax.jacfwd(f))(c0))
        eps = 1e-6
        dc = np.zeros_like(COEFFS)
        dc[0, 1] = eps
        numeric = (np.asarray(f(c0 + dc)) - np.asarray(f(c0 - dc))) / (2 * eps)
    np.testing.assert_allclose(J[..., 0, 1], numeric, rtol=1e-5, atol=1e-6)


def test_wrong_shape_names_the_fisheye_coefficients():
    with pytest.raises(
        ValueError,
        match=r"Fisheye.coeffs must have shape \(M, 4\) = \(k1, k2, k3, k4\) per view; got \(2, 5\)",
    ):
        Fisheye(jnp.zeros((2, 5)))
    with pytest.raises(
        ValueError, match=r"Fisheye.coeffs must have shape \(M, 4\).*M=2; got \(3, 4\)"
    ):
        distort_pixels(jnp.asarray(K_NP), Fisheye(jnp.zeros((3, 4))), jnp.zeros((2, 3, 2)))


def test_matches_opencv_when_installed():
    cv2 = pytest.importorskip("cv2")
    xy = _grid()
    K = K_NP.copy()
    K[1, 0, 1] = 0.0  # cv2.fisheye takes the skew as alpha = K[0,1] / fx: keep both plain
    with x64(True):
        got = np.asarray(distort(jnp.asarray(K), Fisheye(jnp.asarray(COEFFS)), jnp.asarray(xy)))
        back = np.asarray(undistort(jnp.asarray(K), Fisheye(jnp.asarray(COEFFS)), jnp.asarray(got)))
    for m in range(2):
        normalised = (xy[m] - K[m, :2, 2]) / np.diag(K[m])[:2]
        ref = cv2.fisheye.distortPoints(normalised[:, None, :], K[m], COEFFS[m])[:, 0]
        np.testing.assert_allclose(got[m], ref, atol=1e-9)
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-15)
        ref_back = cv2.fisheye.undistortPoints(
            got[m][:, None, :], K[m], COEFFS[m], P=K[m], criteria=criteria
        )[:, 0]
        np.testing.assert_allclose(back[m], ref_back, atol=1e-8)
