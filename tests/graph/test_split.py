import jax
import jax.numpy as jnp
import numpy as np

from cdog_jax import Status
from cdog_jax.graph import EdgeTable, alive_edges, connected_components
from cdog_jax.graph._split import split_conflicts as _split_conflicts

split_conflicts = jax.jit(_split_conflicts, static_argnames=("num_views", "max_iters", "per_node"))


def _edges(pairs, N):
    src = jnp.asarray([p[0] for p in pairs], jnp.int32)
    dst = jnp.asarray([p[1] for p in pairs], jnp.int32)
    A = np.zeros((N, N), bool)
    for u, v in pairs:
        A[u, v] = A[v, u] = True
    return EdgeTable(src, dst, jnp.ones(len(pairs), bool)), jnp.asarray(A)


def test_weakest_edge_removed_first():
    # Views: node u is in view u // 2 (P = 2). A chain 0 - 2 - 4 - 1 holds two nodes of view 0.
    N, M = 6, 3
    edges, A = _edges([(0, 2), (2, 4), (4, 1)], N)
    theta = jnp.asarray([0.9, 0.4, 0.6], jnp.float32)
    dist = jnp.asarray([1.0, 1.0, 1.0], jnp.float32)
    view = jnp.arange(N) // 2
    A2, labels, _ = split_conflicts(A, edges, theta, dist, view, jnp.ones(N, bool), M, max_iters=8)
    assert not bool(A2[2, 4]) and bool(A2[0, 2]) and bool(A2[4, 1])
    assert np.array_equal(np.asarray(labels), [0, 1, 0, 3, 1, 5])


def test_ties_broken_by_larger_distance():
    N, M = 6, 3
    edges, A = _edges([(0, 2), (2, 4), (4, 1)], N)
    theta = jnp.full((3,), 0.5, jnp.float32)
    dist = jnp.asarray([1.0, 2.0, 3.0], jnp.float32)
    A2, _, _ = split_conflicts(
        A, edges, theta, dist, jnp.arange(N) // 2, jnp.ones(N, bool), M, max_iters=8
    )
    assert not bool(A2[4, 1]) and bool(A2[0, 2]) and bool(A2[2, 4])


def test_random_graphs_end_view_unique():
    rng = np.random.default_rng(0)
    for _ in range(5):
        M, P = 4, 5
        N = M * P
        pairs = [(int(u), int(v)) for u, v in rng.integers(0, N, (40, 2)) if u // P != v // P]
        edges, A = _edges(pairs, N)
        E = len(pairs)
        theta = jnp.asarray(rng.random(E), jnp.float32)
        dist = jnp.asarray(rng.random(E), jnp.float32)
        view = jnp.arange(N) // P
        for iters in (1, 64):  # the last resort alone, and the edge-removal loop
            A2, labels, _ = split_conflicts(
                A, edges, theta, dist, view, jnp.ones(N, bool), M, max_iters=iters
            )
            labels = np.asarray(labels)
            assert np.array_equal(
                labels, np.asarray(connected_components(edges, alive_edges(edges, A2), N))
            )
            for c in np.unique(labels):
                views = np.asarray(view)[labels == c]
                assert len(views) == len(set(views))
            assert not np.any(np.asarray(A2) & ~np.asarray(A))  # only removals


def test_split_reports_its_iteration_bound():
    # Chain 0 - 2 - 1 - 3 (P = 2) holds two nodes of view 0 and of view 1: the weakest edge
    # (1, 3) goes first, then (2, 1), so two rounds are needed.
    N, M = 6, 3
    edges, A = _edges([(0, 2), (2, 1), (1, 3)], N)
    theta = jnp.asarray([0.9, 0.3, 0.1], jnp.float32)
    dist = jnp.ones(3, jnp.float32)
    view = jnp.arange(N) // 2
    _, labels, status = split_conflicts(
        A, edges, theta, dist, view, jnp.ones(N, bool), M, max_iters=8
    )
    assert int(status) == 0
    assert np.array_equal(np.asarray(labels), [0, 1, 0, 3, 4, 5])
    _, labels, status = split_conflicts(
        A, edges, theta, dist, view, jnp.ones(N, bool), M, max_iters=1
    )
    assert int(status) == Status.SPLIT_CAPPED  # the last resort decided the rest
    for c in np.unique(np.asarray(labels)):
        views = np.asarray(view)[np.asarray(labels) == c]
        assert len(views) == len(set(views))


def test_split_equals_the_numpy_oracle_with_duplicate_proposals():
    """Random view-structured graphs whose edges are listed once, or twice (u → v and
    v → u), as proposals are: the weakest-edge loop and the last resort give the oracle's
    graph and labels."""
    from oracle import overlap_theta, split_view_unique

    rng = np.random.default_rng(3)
    M, P = 4, 4
    N = M * P
    view = np.arange(N) // P
    for trial in range(6):
        A = np.zeros((N, N), bool)
        for u, v in rng.integers(0, N, (28, 2)):
            if view[u] != view[v]:
                A[u, v] = A[v, u] = True
        theta = overlap_theta(A)
        e = rng.integers(1, 40, (N, N)) / 8.0
        e = np.minimum(e, e.T)  # symmetric distances, as the pipeline's are
        pairs = []
        for u, v in zip(*np.nonzero(np.triu(A))):
            pairs += (
                [(u, v), (v, u)]
                if rng.random() < 0.5
                else [(u, v) if rng.random() < 0.5 else (v, u)]
            )
        src = np.asarray([p[0] for p in pairs], np.int32)
        dst = np.asarray([p[1] for p in pairs], np.int32)
        edges = EdgeTable(jnp.asarray(src), jnp.asarray(dst), jnp.ones(len(pairs), bool))
        for iters in (1, 2, 64):
            A_expected, labels_expected = split_view_unique(A, theta, e, M, P, max_iters=iters)
            A2, labels, _ = split_conflicts(
                jnp.asarray(A),
                edges,
                jnp.asarray(theta[src, dst], jnp.float32),
                jnp.asarray(e[src, dst], jnp.float32),
                jnp.asarray(view),
                jnp.ones(N, bool),
                M,
                max_iters=iters,
            )
            np.testing.assert_array_equal(
                np.asarray(A2), A_expected, err_msg=f"trial {trial}, {iters} iterations"
            )
            np.testing.assert_array_equal(
                np.asarray(labels), labels_expected, err_msg=f"trial {trial}, {iters} iterations"
            )


def test_proposal_tables_split_the_same_by_their_rows():
    """The graph stage's own tables (nearest-neighbour proposals of random scenes, mutual
    adjacency, δ-overlap): splitting with each node's proposals read by rows (``per_node``)
    gives the general path's graph, labels and status, through the loop and the last resort."""
    from cdog_jax.graph._adjacency import adjacency_from_edges, nearest_neighbour_edges
    from cdog_jax.graph._overlap import edge_overlap

    rng = np.random.default_rng(5)
    M, P = 4, 6
    N = M * P
    view = jnp.arange(N) // P
    for trial in range(4):
        d = rng.exponential(3.0, (M, P, M, P)).astype(np.float32)
        for m in range(M):
            d[m, :, m, :] = np.inf
        d[:, P - 1 - trial % 2 :] = np.inf  # empty slots
        edges = nearest_neighbour_edges(jnp.asarray(d), jnp.float32(4.0))
        A = adjacency_from_edges(edges, N, "mutual")
        theta = edge_overlap(edges, A, dtype=jnp.float32)
        dist = jnp.asarray(d.reshape(N, N))[edges.src, edges.dst]
        valid = jnp.asarray(np.isfinite(d.reshape(N, N)).any(axis=1))
        for iters in (1, 64):
            args = (A, edges, theta, dist, view, valid, M)
            general = split_conflicts(*args, max_iters=iters)
            by_rows = split_conflicts(*args, max_iters=iters, per_node=M)
            for a, b in zip(general, by_rows):
                assert np.array_equal(np.asarray(a), np.asarray(b))
