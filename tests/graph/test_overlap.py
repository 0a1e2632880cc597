import jax.numpy as jnp
import numpy as np
import pytest

from cdog_jax.graph import adjacency_from_edges, alive_edges, nearest_neighbour_edges
from cdog_jax.graph._overlap import edge_overlap


def _random_distances(rng, M, P, fill=0.7):
    d = rng.exponential(3.0, (M, P, M, P))
    mask = rng.random((M, P)) < fill
    for m in range(M):
        d[m, :, m, :] = np.inf
    d[~mask] = np.inf
    d[:, :, ~mask] = np.inf
    return d, mask


def _nearest_np(d, tau):
    M, P = d.shape[:2]
    D = np.zeros((M * P, M * P), bool)
    for m in range(M):
        for i in range(P):
            for n in range(M):
                j = int(np.argmin(d[m, i, n]))
                if d[m, i, n, j] < tau:
                    D[m * P + i, n * P + j] = True
    return D


@pytest.mark.parametrize("mode", ["mutual", "union"])
@pytest.mark.parametrize("seed", range(6))
def test_overlap_equals_dense_formula(mode, seed):
    rng = np.random.default_rng(seed)
    M, P = int(rng.integers(2, 6)), int(rng.integers(1, 9))
    d, _ = _random_distances(rng, M, P)
    tau = 4.0
    edges = nearest_neighbour_edges(jnp.asarray(d, jnp.float32), jnp.float32(tau))
    A = np.asarray(adjacency_from_edges(edges, M * P, mode))
    D = _nearest_np(d, tau)
    want_A = (D & D.T) if mode == "mutual" else (D | D.T)
    assert np.array_equal(A, want_A)
    # Literal formula: C = A + I, O = C Cᵀ, θ = O / max(deg, deg).
    C = want_A.astype(float) + np.eye(M * P)
    O = C @ C.T
    deg = C.sum(1)
    theta = np.asarray(edge_overlap(edges, jnp.asarray(A)))
    alive = np.asarray(alive_edges(edges, jnp.asarray(A)))
    src, dst = np.asarray(edges.src), np.asarray(edges.dst)
    for e in np.flatnonzero(alive):
        u, v = src[e], dst[e]
        assert theta[e] == pytest.approx(O[u, v] / max(deg[u], deg[v]), abs=1e-6)
    # Every edge of A is represented by at least one alive proposal.
    covered = np.zeros_like(A)
    covered[src[alive], dst[alive]] = True
    assert np.array_equal(covered | covered.T, A)
