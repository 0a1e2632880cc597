import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cdog_jax.graph import EdgeTable, connected_components
from cdog_jax.graph._components import connected_components_capped


def _union_find(n, pairs):
    parent = list(range(n))

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for u, v in pairs:
        ru, rv = find(u), find(v)
        if ru != rv:
            parent[max(ru, rv)] = min(ru, rv)
    roots = [find(a) for a in range(n)]
    smallest = {}
    for a, r in enumerate(roots):
        smallest.setdefault(r, a)
    return np.array([smallest[r] for r in roots])


@pytest.mark.parametrize("seed", range(8))
def test_components_equal_union_find(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 60))
    E = int(rng.integers(0, 2 * n))
    src = rng.integers(0, n, E)
    dst = rng.integers(0, n, E)
    alive = rng.random(E) < 0.7
    edges = EdgeTable(jnp.asarray(src, jnp.int32), jnp.asarray(dst, jnp.int32), jnp.ones(E, bool))
    got = np.asarray(connected_components(edges, jnp.asarray(alive), n))
    want = _union_find(n, [(u, v) for u, v, a in zip(src, dst, alive) if a])
    assert np.array_equal(got, want)


def test_long_path_converges():
    n = 200
    perm = np.random.default_rng(0).permutation(n)
    src, dst = perm[:-1], perm[1:]
    edges = EdgeTable(
        jnp.asarray(src, jnp.int32), jnp.asarray(dst, jnp.int32), jnp.ones(n - 1, bool)
    )
    got = np.asarray(connected_components(edges, jnp.ones(n - 1, bool), n))
    assert np.all(got == 0)


def test_round_bound_is_reported():
    # A path of 200 nodes in random order: the default bound (N rounds) always suffices,
    # a bound of 2 rounds does not and says so.
    n = 200
    perm = np.random.default_rng(0).permutation(n)
    edges = EdgeTable(
        jnp.asarray(perm[:-1], jnp.int32), jnp.asarray(perm[1:], jnp.int32), jnp.ones(n - 1, bool)
    )
    alive = jnp.ones(n - 1, bool)
    labels, capped = connected_components_capped(edges, alive, n)
    assert not bool(capped) and np.all(np.asarray(labels) == 0)
    labels, capped = connected_components_capped(edges, alive, n, max_rounds=2)
    assert bool(capped) and np.any(np.asarray(labels) != 0)


_CAPPED = jax.jit(
    connected_components_capped, static_argnums=2, static_argnames=("max_rounds", "per_node")
)


@pytest.mark.parametrize("seed", range(4))
def test_proposal_tables_give_the_same_labels_by_their_rows(seed):
    """The pipeline's proposal tables (each node's ``M`` proposals in a row, a node that
    proposes nothing pointing at itself): reading the sources by rows (``per_node``) gives the
    labels of the general path round by round (any bound) and union-find's at the end."""
    rng = np.random.default_rng(seed)
    M, P = int(rng.integers(2, 6)), int(rng.integers(1, 12))
    n = M * P
    src = np.repeat(np.arange(n), M)
    ok = rng.random(n * M) < 0.5
    dst = np.where(ok, rng.integers(0, n, n * M), src)
    alive = ok & (rng.random(n * M) < 0.8)
    edges = EdgeTable(jnp.asarray(src, jnp.int32), jnp.asarray(dst, jnp.int32), jnp.asarray(ok))
    for bound in (1, 2, None):
        general = _CAPPED(edges, jnp.asarray(alive), n, max_rounds=bound)
        by_rows = _CAPPED(edges, jnp.asarray(alive), n, max_rounds=bound, per_node=M)
        assert np.array_equal(np.asarray(by_rows[0]), np.asarray(general[0]))
        assert bool(by_rows[1]) == bool(general[1])
    want = _union_find(n, [(u, v) for u, v, a in zip(src, dst, alive) if a])
    assert np.array_equal(np.asarray(by_rows[0]), want)
