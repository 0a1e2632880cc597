import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import TOL, project_np, ring_rig, x64

from cdog_jax import triangulate
from cdog_jax.geometry import dlt_blocks, project
from cdog_jax.geometry._triangulate import triangulate_pairs


@pytest.mark.parametrize("dtype", ["float32", "float64"])
@pytest.mark.parametrize("negate", [(), (0, 2)])
def test_dlt_exact_without_noise(dtype, negate):
    with x64(dtype == "float64"):
        rig = ring_rig(5, negate=negate, dtype=dtype)
        X = np.random.default_rng(0).uniform(-0.5, 0.5, (200, 3))
        xy, _ = project_np(rig, X)
        tracks = jnp.asarray(xy, dtype)  # (M, n, 2): the view axis first
        mask = np.random.default_rng(1).random((5, 200)) < 0.6
        mask[:2] = True  # at least two views per track
        got, ok = triangulate(rig, tracks, jnp.asarray(mask))
    assert np.all(np.asarray(ok))
    rel = np.abs(np.asarray(got, np.float64) - X).max() / 1.0  # scene size ~1 unit
    assert rel < TOL[dtype]["rel"] * (10 if dtype == "float64" else 1)


def test_masked_views_ignored_and_single_view_flagged():
    rig = ring_rig(4)
    X = np.array([[0.1, -0.2, 0.3]])
    xy, _ = project_np(rig, X)
    tracks = xy.copy()
    tracks[3, 0] = [1e6, -1e6]  # garbage where masked
    got, ok = triangulate(
        rig, jnp.asarray(tracks, jnp.float32), jnp.array([[True], [True], [False], [False]])
    )
    assert bool(ok[0]) and np.abs(np.asarray(got[0]) - X[0]).max() < 1e-4
    _, ok1 = triangulate(
        rig, jnp.asarray(tracks, jnp.float32), jnp.array([[True], [False], [False], [False]])
    )
    assert not bool(ok1[0])


def test_pairs_reproject_onto_their_observations():
    rig = ring_rig(4)
    X = np.array([[0.2, 0.1, -0.1]])
    xy, _ = project_np(rig, X)
    N, r, origin = dlt_blocks(rig, jnp.asarray(xy[:, 0], jnp.float32))
    Xp, ok = triangulate_pairs(N, r, origin)
    assert np.array_equal(np.asarray(ok), ~np.eye(4, dtype=bool))
    reproj, _ = project(rig, Xp)  # (M, M, M, 2): view, then the pair (a, b)
    err = np.abs(np.asarray(reproj) - xy[:, 0][:, None, None]).max(axis=-1).max(axis=0)
    assert err[np.asarray(ok)].max() < 1e-2


def test_gradient_finite_through_dlt():
    rig = ring_rig(3)
    X = np.array([[0.0, 0.1, 0.2]])
    xy, _ = project_np(rig, X)
    tracks = jnp.asarray(xy, jnp.float32)

    def loss(tr):
        Xh, _ = triangulate(rig, tr, jnp.ones((3, 1), bool))
        return jnp.sum(Xh**2)

    g = jax.grad(loss)(tracks)
    assert np.all(np.isfinite(np.asarray(g)))


def _tracks(rig, n, seed):
    X = np.random.default_rng(seed).uniform(-0.5, 0.5, (n, 3))
    xy, _ = project_np(rig, X)
    return X, xy.copy()  # (M, n, 2)


@pytest.mark.parametrize("garbage", [np.nan, np.inf, -np.inf, 1e30])
def test_masked_entries_change_nothing(garbage):
    rig = ring_rig(4)
    X, tracks = _tracks(rig, 30, 2)
    mask = np.random.default_rng(3).random((4, 30)) < 0.7
    mask[:2] = True
    clean = np.where(mask[..., None], tracks, 0.0)
    dirty = np.where(mask[..., None], tracks, garbage)
    p0, ok0 = triangulate(rig, jnp.asarray(clean, jnp.float32), jnp.asarray(mask))
    p1, ok1 = triangulate(rig, jnp.asarray(dirty, jnp.float32), jnp.asarray(mask))
    assert np.asarray(ok0).all()
    np.testing.assert_array_equal(np.asarray(ok1), np.asarray(ok0))
    np.testing.assert_array_equal(np.asarray(p1), np.asarray(p0))
    g = jax.grad(lambda tr: jnp.sum(triangulate(rig, tr, jnp.asarray(mask))[0] ** 2))(
        jnp.asarray(dirty, jnp.float32)
    )
    assert np.all(np.isfinite(np.asarray(g)))


def test_mask_none_means_finite_entries_are_observed():
    rig = ring_rig(4)
    X, tracks = _tracks(rig, 30, 4)
    tracks[3] = np.nan  # anipose / DeepLabCut: NaN for a missing view
    tracks[2, ::2] = np.nan
    p, ok = triangulate(rig, jnp.asarray(tracks, jnp.float32), None)
    assert np.asarray(ok).all()
    assert np.abs(np.asarray(p) - X).max() < 1e-3
    one = tracks.copy()
    one[1:] = np.nan
    _, ok1 = triangulate(rig, jnp.asarray(one, jnp.float32), None)
    assert not np.asarray(ok1).any()


def test_single_views_are_never_ok_in_float32():
    rig = ring_rig(4)
    n = 148
    _, tracks = _tracks(rig, n, 5)
    mask = np.zeros((4, n), bool)
    mask[np.arange(n) % 4, np.arange(n)] = True
    _, ok = triangulate(rig, jnp.asarray(tracks, jnp.float32), jnp.asarray(mask))
    assert int(np.sum(ok)) == 0
    # Two views of which one has weight 0: one view counts.
    mask2 = mask.copy()
    mask2[(np.arange(n) + 1) % 4, np.arange(n)] = True
    weights = np.where(mask, 0.0, 1.0)
    _, ok2 = triangulate(
        rig,
        jnp.asarray(tracks, jnp.float32),
        jnp.asarray(mask2),
        weights=jnp.asarray(weights, jnp.float32),
    )
    assert int(np.sum(ok2)) == 0
    _, ok3 = triangulate(rig, jnp.asarray(tracks, jnp.float32), jnp.asarray(mask2))
    assert np.asarray(ok3).all()
