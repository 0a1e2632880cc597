"""The built-in benchmark rig (docs/BENCHMARK.md §1) and negated intrinsics (docs/CONVENTIONS.md §1)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cdog_jax.geometry._projection import project
from cdog_jax.synthetic import DEFAULT_BOX, IMAGE_SIZE, default_rig
from cdog_jax.synthetic._rig import look_at_rotation, negate_intrinsics

LO, HI = (np.asarray(c) for c in DEFAULT_BOX)
CENTER = 0.5 * (LO + HI)


def _uniform_points(n, seed=0):
    return np.random.default_rng(seed).uniform(LO, HI, size=(n, 3))


project_points = jax.jit(jax.vmap(project, in_axes=(None, 0)))  # (S, 3) → (S, M, 2), (S, M)


def _visible(rig, X):
    xy, front = project_points(rig, jnp.asarray(X, rig.K.dtype))
    w, h = IMAGE_SIZE
    x, y = xy[..., 0], xy[..., 1]
    return np.asarray(front & (x >= 0) & (x < w) & (y >= 0) & (y < h))


def test_shapes_dtype_and_determinism():
    rig = default_rig()
    assert rig.K.shape == (10, 3, 3) and rig.R.shape == (10, 3, 3) and rig.t.shape == (10, 3)
    assert rig.K.dtype == jnp.asarray(0.0).dtype
    again = default_rig()
    for a, b in ((rig.K, again.K), (rig.R, again.R), (rig.t, again.t)):
        np.testing.assert_array_equal(a, b)
    assert default_rig(num_views=4).num_views == 4
    with pytest.raises(ValueError, match="num_views"):
        default_rig(num_views=0)


def test_intrinsics_like_easyvis():
    K = np.asarray(default_rig().K, np.float64)
    np.testing.assert_allclose(K[:, 0, 0], 1302.0, atol=10.0)
    np.testing.assert_array_equal(K[:, 0, 0], K[:, 1, 1])
    np.testing.assert_allclose(K[:, 0, 2], 320.0, atol=10.0)
    np.testing.assert_allclose(K[:, 1, 2], 240.0, atol=10.0)
    np.testing.assert_array_equal(K[:, 2], np.broadcast_to([0.0, 0.0, 1.0], (10, 3)))
    np.testing.assert_array_equal(K[:, 1, 0], 0.0)


def test_rotations_orthonormal():
    R = np.asarray(default_rig().R, np.float64)
    np.testing.assert_allclose(
        np.einsum("mji,mjk->mik", R, R), np.broadcast_to(np.eye(3), R.shape), atol=1e-5
    )
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-5)


def test_cameras_one_side_at_1_to_5_units():
    rig = default_rig()
    C = np.asarray(rig.centers, np.float64)
    dist_center = np.linalg.norm(C - CENTER[None], axis=-1)
    assert np.all((dist_center >= 1.0) & (dist_center <= 5.0)), dist_center
    corners = np.array(
        [[a, b, c] for a in (LO[0], HI[0]) for b in (LO[1], HI[1]) for c in (LO[2], HI[2])]
    )
    dist_points = np.linalg.norm(C[:, None] - corners[None], axis=-1)
    assert dist_points.min() >= 1.0 and dist_points.max() <= 5.0
    # One side: every camera is above the box top and looks down towards the box centre.
    assert np.all(C[:, 2] > HI[2])
    to_center = CENTER[None] - C
    to_center /= np.linalg.norm(to_center, axis=-1, keepdims=True)
    cos = np.sum(np.asarray(rig.view_dirs, np.float64) * to_center, axis=-1)
    assert np.all(cos > np.cos(np.deg2rad(15.0)))


def test_mean_views_per_point():
    vis = _visible(default_rig(), _uniform_points(50_000))
    mean_views = vis.sum(-1).mean()
    assert 4.3 <= mean_views <= 5.3, mean_views
    assert vis.any(0).all()  # every camera sees part of the box


def test_look_at_rotation():
    center, target = np.array([2.0, -1.0, 3.0]), np.array([0.1, 0.2, 0.3])
    R = look_at_rotation(center, target)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    X_cam = R @ (target - center)
    np.testing.assert_allclose(X_cam[:2], 0.0, atol=1e-12)
    assert X_cam[2] > 0
    # World up points up in the image (negative y in OpenCV axes).
    assert (R @ np.array([0.0, 0.0, 1.0]))[1] < 0
    with pytest.raises(ValueError, match="parallel"):
        look_at_rotation([0.0, 0.0, 2.0], [0.0, 0.0, 0.0])


def test_negate_intrinsics_keeps_projections():
    rig = default_rig()
    neg = negate_intrinsics(rig, [0, 3, 7])
    np.testing.assert_array_equal(np.asarray(neg.K[:, 2, 2]), [-1, 1, 1, -1, 1, 1, 1, -1, 1, 1])
    np.testing.assert_array_equal(neg.R, rig.R)
    X = jnp.asarray(_uniform_points(1000, seed=1), rig.K.dtype)
    xy, ok = project_points(rig, X)
    xy_neg, ok_neg = project_points(neg, X)
    np.testing.assert_array_equal(ok, ok_neg)
    np.testing.assert_allclose(xy_neg, xy, atol=1e-3)
