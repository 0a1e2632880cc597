"""One axis order: every per-view array puts the view axis first (detections ``(M, P, 2)``,
tracks ``(M, N, 2)``), so projecting and triangulating compose without transposes; the lens
goes in through ``dist=``."""

import jax.numpy as jnp
import numpy as np
from helpers import project_np, ring_rig

from cdog_jax import project, triangulate
from cdog_jax.geometry import Fisheye, camera_points, dlt_blocks, in_front, reprojection_errors

X = np.random.default_rng(7).uniform(-0.5, 0.5, (12, 3))
DIST = np.array([[-0.2, 0.05, 1e-3, -1e-3, 0.01]] * 4)


def test_project_and_triangulate_compose_view_axis_first():
    rig = ring_rig(4)
    xy, ok = project(rig, jnp.asarray(X, jnp.float32))
    assert xy.shape == (4, 12, 2) and ok.shape == (4, 12)
    np.testing.assert_allclose(np.asarray(xy), project_np(rig, X)[0], atol=1e-3)
    points, determined = triangulate(rig, xy, ok)
    assert points.shape == (12, 3) and bool(determined.all())
    np.testing.assert_allclose(np.asarray(points), X, atol=1e-4)
    N, r, _ = dlt_blocks(rig, xy)
    assert N.shape == (4, 12, 3, 3) and r.shape == (4, 12, 3)
    err = reprojection_errors(rig, points, xy)
    assert err.shape == (4, 12) and float(err.max()) < 1e-2
    assert camera_points(rig, jnp.asarray(X, jnp.float32)).shape == (4, 12, 3)
    assert in_front(rig, jnp.asarray(X, jnp.float32)).shape == (4, 12)


def test_dist_on_project_and_triangulate():
    rig = ring_rig(4)
    Xj = jnp.asarray(X, jnp.float32)
    ideal, ok = project(rig, Xj)
    for lens in (jnp.asarray(DIST, jnp.float32), Fisheye(jnp.asarray([[0.05, -0.01, 0.0, 0.0]] * 4, jnp.float32))):
        recorded, ok_d = project(rig, Xj, dist=lens)
        assert float(jnp.abs(recorded - ideal).max()) > 1.0  # the lens moves pixels
        np.testing.assert_array_equal(np.asarray(ok_d), np.asarray(ok))
        recorded = recorded.at[3, 0].set(jnp.nan)  # a masked, missing view
        mask = ok.at[3, 0].set(False)
        points, determined = triangulate(rig, recorded, mask, dist=lens)
        assert bool(determined.all())
        error = np.abs(np.asarray(points) - X).max()
        assert error < 2e-4
        # Without the lens the points are off.
        wrong, _ = triangulate(rig, recorded, mask)
        assert np.abs(np.asarray(wrong) - X).max() > 10 * error
