"""CCA (connected components of the mutual-nearest-neighbour epipolar graph, split to
view-uniqueness): conformance, and agreement with a plain NumPy version of the cuts.

Noise-free bound: every point seen in ≥ 2 views is grouped exactly when every pair of
detections of different points has symmetric epipolar cost ≥ τ. Then the only edges are
same-point pairs; each detection's partner in every view of its point is its unique
cheapest one (cost ≈ 0), so every same-point pair is a mutual nearest neighbour and the
components are the points, none of which needs a split.
"""

import numpy as np
from pairwise_baseline_checks import conformance, distances, gate, group_sets, jitted, random_scene

from cdog_jax.baselines._components import ComponentsOptions, components_groups


def cca_numpy(d, mask, tau, max_rounds):
    """Independent version, literally: explicit edge set, components by depth-first search,
    one most-expensive edge (ties: smallest node pair) cut per conflicting component per
    round, components again. Returns the groups and the rounds used (at most
    ``max_rounds``)."""
    d = np.where(mask[:, :, None, None] & mask[None, None] & ~np.isnan(d), d, np.inf).astype(
        np.float32
    )
    c = np.float32(0.5) * (d + d.transpose(2, 3, 0, 1))
    M, P = mask.shape
    N = M * P
    cost = c.reshape(N, N)
    nearest = {}
    for u in range(N):
        for n in range(M):
            if n != u // P:
                row = cost[u, n * P : (n + 1) * P]
                j = int(np.argmin(row))
                if row[j] < tau:
                    nearest[u, n] = n * P + j
    edges = {(u, v) for (u, n), v in nearest.items() if u < v and nearest.get((v, u // P)) == u}

    def components():
        adj = {u: [] for u in range(N)}
        for u, v in edges:
            adj[u].append(v)
            adj[v].append(u)
        seen, comps = set(), []
        for u in range(N):
            if u not in seen and mask.reshape(N)[u]:
                stack, comp = [u], set()
                while stack:
                    w = stack.pop()
                    if w not in comp:
                        comp.add(w)
                        stack.extend(adj[w])
                seen |= comp
                comps.append(comp)
        return comps

    def conflicting(comp):
        views = [w // P for w in comp]
        return len(views) != len(set(views))

    for rounds in range(max_rounds + 1):
        bad = [comp for comp in components() if conflicting(comp)]
        if not bad:
            break
        assert rounds < max_rounds, "max_rounds too small"
        for comp in bad:
            inside = [(u, v) for u, v in edges if u in comp]
            edges.remove(max(inside, key=lambda e: (cost[e], -e[0], -e[1])))
    groups = {frozenset((w // P, w % P) for w in comp) for comp in components() if len(comp) >= 2}
    return groups, rounds


def test_cca_conformance():
    conformance(components_groups, ComponentsOptions())


def test_cca_matches_numpy():
    f = jitted(components_groups, ComponentsOptions())
    rounds_seen = []
    for seed, sigma in [
        (1, 1.0),
        (2, 3.0),
        (3, 3.0),
        (4, 5.0),
        (9, 5.0),
        (1, 10.0),
        (9, 10.0),
        (1, 15.0),
    ]:
        rig, s = random_scene(seed, sigma, num_points=12)
        g, v, st = f(rig, s.xy, s.mask, np.float32(sigma))
        d = np.asarray(distances(rig, s.xy, s.mask))
        want, rounds = cca_numpy(d, np.asarray(s.mask), np.float32(gate(sigma)), 10_000)
        rounds_seen.append(rounds)
        assert group_sets(g, v) == want and int(st) == 0, f"seed {seed}"
    # Scenes whose components take several rounds of cuts, or the comparison says little.
    assert sum(rounds_seen) >= 30 and max(rounds_seen) >= 8, rounds_seen
