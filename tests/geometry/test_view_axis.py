"""One axis order: every per-view array puts the view axis first (detections ``(M, P, 2)``,
tracks ``(M, N, 2)``), so projecting and triangulating compose without transposes; the lens
goes in through ``dist=``."""

import jax
import jax.numpy as jnp
import numpy as np
from helpers import project_np, ring_rig

from cdog_jax import project, triangulate
from cdog_jax.geometry import Fisheye, camera_points, dlt_blocks, in_front, reprojection_errors

X = np.random.default_rng(7).uniform(-0.5, 0.5, (12, 3))
DIST = np.array([[-0.2, 0.05, 1e-3, -1e-3, 0.01]] * 4)


@jax.jit
def _compose(rig, X):
    xy, ok = project(rig, X)
    points, determined = triangulate(rig, xy, ok)
    N, r, _ = dlt_blocks(rig, xy)
    return (
        xy,
        ok,
        points,
        determined,
        N,
        r,
        reprojection_errors(rig, points, xy),
        camera_points(rig, X),
        in_front(rig, X),
    )


def test_project_and_triangulate_compose_view_axis_first():
    rig = ring_rig(4)
    xy, ok, points, determined, N, r, err, X_cam, front = _compose(rig, jnp.asarray(X, jnp.float32))
    assert xy.shape == (4, 12, 2) and ok.shape == (4, 12)
    np.testing.assert_allclose(np.asarray(xy), project_np(rig, X)[0], atol=1e-3)
    assert points.shape == (12, 3) and bool(determined.all())
    np.testing.assert_allclose(np.asarray(points), X, atol=1e-4)
    assert N.shape == (4, 12, 3, 3) and r.shape == (4, 12, 3)
    assert err.shape == (4, 12) and float(err.max()) < 1e-2
    assert X_cam.shape == (4, 12, 3) and front.shape == (4, 12) and bool(front.all())


@jax.jit
def _through_lens(rig, X, lens):
    ideal, ok = project(rig, X)
    recorded, ok_d = project(rig, X, dist=lens)
    recorded = recorded.at[3, 0].set(jnp.nan)  # a masked, missing view
    mask = ok.at[3, 0].set(False)
    points, determined = triangulate(rig, recorded, mask, dist=lens)
    wrong, _ = triangulate(rig, recorded, mask)
    return ideal, ok, recorded, ok_d, points, determined, wrong


def test_dist_on_project_and_triangulate():
    rig = ring_rig(4)
    for lens in (
        jnp.asarray(DIST, jnp.float32),
        Fisheye(jnp.asarray([[0.05, -0.01, 0.0, 0.0]] * 4, jnp.float32)),
    ):
        ideal, ok, recorded, ok_d, points, determined, wrong = _through_lens(
            rig, jnp.asarray(X, jnp.float32), lens
        )
        assert float(jnp.nanmax(jnp.abs(recorded - ideal))) > 1.0  # the lens moves pixels
        np.testing.assert_array_equal(np.asarray(ok_d), np.asarray(ok))
        assert bool(determined.all())
        error = np.abs(np.asarray(points) - X).max()
        assert error < 2e-4
        # Without the lens the points are off.
        assert np.abs(np.asarray(wrong) - X).max() > 10 * error
