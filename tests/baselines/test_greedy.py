"""Greedy epipolar matching: conformance, and agreement with a plain NumPy version.

Noise-free bound: every point seen in ≥ 2 views is grouped exactly when every pair of
detections of different points has symmetric epipolar cost ≥ τ. Then the candidate edges
below τ are exactly the same-point pairs, and merging all of them can never put two
detections of one view together.
"""

import numpy as np
import pytest
from pairwise_baseline_checks import conformance, distances, gate, group_sets, jitted, random_scene

from cdog_jax.baselines._greedy import GreedyOptions, greedy_groups


def greedy_numpy(d, mask, tau, k):
    """Independent version: plain loops over every node, other view and its k cheapest
    partners; union-find over Python sets."""
    d = np.where(mask[:, :, None, None] & mask[None, None] & ~np.isnan(d), d, np.inf).astype(
        np.float32
    )
    c = np.float32(0.5) * (d + d.transpose(2, 3, 0, 1))
    M, P = mask.shape
    edges = set()
    for m in range(M):
        for i in range(P):
            for n in range(M):
                if n == m:
                    continue
                for j in np.argsort(c[m, i, n], kind="stable")[:k]:
                    if c[m, i, n, j] < tau:
                        u, v = sorted((m * P + i, n * P + int(j)))
                        edges.add((float(c[m, i, n, j]), u, v))
    group = {u: {u} for u in range(M * P)}
    for _, u, v in sorted(edges):
        gu, gv = group[u], group[v]
        if gu is gv or {w // P for w in gu} & {w // P for w in gv}:
            continue
        merged = gu | gv
        for w in merged:
            group[w] = merged
    found = {frozenset(g) for g in map(frozenset, group.values()) if len(g) >= 2}
    return {frozenset((w // P, w % P) for w in g) for g in found}


def test_greedy_conformance():
    conformance(greedy_groups, GreedyOptions())


@pytest.mark.parametrize("k", [1, 2])
def test_greedy_matches_numpy(k):
    options = GreedyOptions(candidates_per_view=k)
    f = jitted(greedy_groups, options)
    for seed, sigma in [(1, 1.0), (2, 3.0), (3, 3.0), (4, 5.0), (5, 5.0)]:
        rig, s = random_scene(seed, sigma, num_points=10)
        g, v, _ = f(rig, s.xy, s.mask, np.float32(sigma))
        d = np.asarray(distances(rig, s.xy, s.mask))
        assert group_sets(g, v) == greedy_numpy(
            d, np.asarray(s.mask), np.float32(gate(sigma)), k
        ), f"seed {seed}"


def test_greedy_options_checked():
    with pytest.raises(ValueError, match="candidates_per_view"):
        GreedyOptions(candidates_per_view=0)
