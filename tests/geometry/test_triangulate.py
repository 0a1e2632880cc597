import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import TOL, project_np, ring_rig, x64

from cdog_jax import triangulate
from cdog_jax.geometry import dlt_blocks, project, triangulate_pairs


@pytest.mark.parametrize("dtype", ["float32", "float64"])
@pytest.mark.parametrize("negate", [(), (0, 2)])
def test_dlt_exact_without_noise(dtype, negate):
    with x64(dtype == "float64"):
        rig = ring_rig(5, negate=negate, dtype=dtype)
        X = np.random.default_rng(0).uniform(-0.5, 0.5, (200, 3))
        xy, _ = project_np(rig, X)
        tracks = jnp.asarray(np.transpose(xy, (1, 0, 2)), dtype)  # (n, M, 2)
        mask = np.random.default_rng(1).random((200, 5)) < 0.6
        mask[:, :2] = True  # at least two views per track
        got, ok = triangulate(rig, tracks, jnp.asarray(mask))
    assert np.all(np.asarray(ok))
    rel = np.abs(np.asarray(got, np.float64) - X).max() / 1.0  # scene size ~1 unit
    assert rel < TOL[dtype]["rel"] * (10 if dtype == "float64" else 1)


def test_masked_views_ignored_and_single_view_flagged():
    rig = ring_rig(4)
    X = np.array([[0.1, -0.2, 0.3]])
    xy, _ = project_np(rig, X)
    tracks = np.transpose(xy, (1, 0, 2)).copy()
    tracks[0, 3] = [1e6, -1e6]  # garbage where masked
    got, ok = triangulate(rig, jnp.asarray(tracks, jnp.float32), jnp.array([[True, True, False, False]]))
    assert bool(ok[0]) and np.abs(np.asarray(got[0]) - X[0]).max() < 1e-4
    _, ok1 = triangulate(rig, jnp.asarray(tracks, jnp.float32), jnp.array([[True, False, False, False]]))
    assert not bool(ok1[0])


def test_pairs_reproject_onto_their_observations():
    rig = ring_rig(4)
    X = np.array([[0.2, 0.1, -0.1]])
    xy, _ = project_np(rig, X)
    N, r, origin = dlt_blocks(rig, jnp.asarray(xy[:, 0], jnp.float32))
    Xp, ok = triangulate_pairs(N, r, origin)
    assert np.array_equal(np.asarray(ok), ~np.eye(4, dtype=bool))
    reproj, _ = project(rig, Xp)  # (M, M, M, 2)
    err = np.abs(np.asarray(reproj) - xy[:, 0][None, None]).max(axis=-1)
    assert err[np.asarray(ok)].max() < 1e-2


def test_gradient_finite_through_dlt():
    rig = ring_rig(3)
    X = np.array([[0.0, 0.1, 0.2]])
    xy, _ = project_np(rig, X)
    tracks = jnp.asarray(np.transpose(xy, (1, 0, 2)), jnp.float32)

    def loss(tr):
        Xh, _ = triangulate(rig, tr, jnp.ones((1, 3), bool))
        return jnp.sum(Xh**2)

    g = jax.grad(loss)(tracks)
    assert np.all(np.isfinite(np.asarray(g)))
