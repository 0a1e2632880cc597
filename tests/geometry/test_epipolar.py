import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import TOL, project_np, ring_rig, x64

from cdog_jax.geometry import epipolar_distances, fundamental_from_rig


@pytest.mark.parametrize("negate", [(), (1, 3)])
def test_fundamental_annihilates_exact_projections(negate):
    with x64():
        rig = ring_rig(5, negate=negate, dtype=np.float64)
        F = np.asarray(fundamental_from_rig(rig))
    X = np.random.default_rng(0).uniform(-0.5, 0.5, (50, 3))
    xy, _ = project_np(rig, X)
    xh = np.concatenate([xy, np.ones(xy.shape[:2] + (1,))], -1)  # (M, n, 3)
    for m in range(5):
        for n in range(5):
            if m == n:
                assert np.allclose(F[m, n], 0)
                continue
            res = np.einsum("ki,ij,kj->k", xh[n], F[m, n], xh[m])
            lines = xh[m] @ F[m, n].T
            dist = np.abs(res) / np.linalg.norm(lines[:, :2], axis=1)
            assert dist.max() < 1e-8


def _dist_np(rig, xy, mask):
    """Point-to-epipolar-line distances with the literal pixel F (float64)."""
    K, R, t = (np.asarray(a, np.float64) for a in (rig.K, rig.R, rig.t))
    M, P = mask.shape
    d = np.full((M, P, M, P), np.inf)
    for m in range(M):
        for n in range(M):
            if m == n:
                continue
            R_rel = R[n] @ R[m].T
            t_rel = t[n] - R_rel @ t[m]
            tx = np.array(
                [[0, -t_rel[2], t_rel[1]], [t_rel[2], 0, -t_rel[0]], [-t_rel[1], t_rel[0], 0]]
            )
            F = np.linalg.inv(K[n]).T @ tx @ R_rel @ np.linalg.inv(K[m])
            for i in range(P):
                if not mask[m, i]:
                    continue
                line = F @ np.array([*xy[m, i], 1.0])
                for j in range(P):
                    if mask[n, j]:
                        d[m, i, n, j] = abs(line @ np.array([*xy[n, j], 1.0])) / np.hypot(
                            line[0], line[1]
                        )
    return d


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_distance_table_matches_literal_formula(dtype):
    rig = ring_rig(4, negate=(2,))  # float32 parameters, used as exact values in both dtypes
    rng = np.random.default_rng(1)
    xy = rng.uniform([0, 0], [640, 480], (4, 6, 2))
    mask = rng.random((4, 6)) < 0.8
    want = _dist_np(rig, xy, mask)
    with x64(dtype == "float64"):
        rig_d = jax.tree.map(lambda a: jnp.asarray(a, dtype), rig)
        got = np.asarray(epipolar_distances(rig_d, jnp.asarray(xy, dtype), jnp.asarray(mask)))
    finite = np.isfinite(want)
    assert np.array_equal(finite, np.isfinite(got))
    tol = 1e-2 if dtype == "float32" else 1e-8
    assert np.abs(got[finite] - want[finite]).max() < tol


def test_true_matches_at_zero_distance_float32():
    rig = ring_rig(5, negate=(0,))
    X = np.random.default_rng(2).uniform(-0.5, 0.5, (30, 3))
    xy, _ = project_np(rig, X)
    d = np.asarray(epipolar_distances(rig, jnp.asarray(xy, jnp.float32), jnp.ones((5, 30), bool)))
    diag = np.stack([d[m, :, n, :].diagonal() for m in range(5) for n in range(5) if m != n])
    assert diag.max() < TOL["float32"]["px"]
