"""The exact reference: its integer program finds the best partition into cliques (checked
against brute force on tiny scenes), it is never worse in that cost than greedy's or
voting's groups, and it is a host method that every entry point runs eagerly."""

import itertools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import random_scene, ring_rig

from cdog_jax import associate, associate_batch
from cdog_jax.baselines import Exact
from cdog_jax.baselines._exact import MAX_POINTS, clique_cost, exact_groups, gated_cost
from cdog_jax.benchmark import Grid, sweep
from cdog_jax.geometry import epipolar_distances

RIG3 = ring_rig(3)
SIGMA = 3.0
TAU = max(2.0 * math.sqrt(2.0) * SIGMA, 1.0)
distances = jax.jit(epipolar_distances)


def _tiny_scenes(count=10, points=4, P=4):
    """3 views, ≤ 4 points in a small box and σ = 3 px: many competing cliques."""
    out = []
    for seed in range(count):
        xy, mask, inst, _ = random_scene(RIG3, points, P, sigma=SIGMA, seed=300 + seed, box=0.25)
        out.append((xy.astype(np.float32), mask, inst))
    return out


def _brute_force(cost, nodes, tau):
    """The least total cost over all partitions of ``nodes`` into groups that are cliques of
    the gated graph (``cost < tau`` between every two members; singletons cost 0), by trying
    every group that holds the smallest remaining node. Returns (cost, partition)."""
    cliques = [
        frozenset(s)
        for k in range(2, len(nodes) + 1)
        for s in itertools.combinations(nodes, k)
        if all(cost[a, b] < tau for a, b in itertools.combinations(s, 2))
    ]

    def best(left: frozenset):
        if not left:
            return 0.0, frozenset()
        u = min(left)
        value, partition = best(left - {u})  # u alone
        for c in cliques:
            if u in c and c <= left:
                v, p = best(left - c)
                v += sum(cost[a, b] - tau for a, b in itertools.combinations(sorted(c), 2))
                if v < value - 1e-9:
                    value, partition = v, p | {c}
        return value, partition

    return best(frozenset(nodes))


def _sets(groups, valid, P):
    return {
        frozenset(m * P + int(s) for m, s in enumerate(row) if s >= 0)
        for row in np.asarray(groups)[np.asarray(valid)]
    }


def _competing(cost, tau, P):
    """Some detection has gated partners in one view that are not gated with each other's
    partners: more than one clique could take it."""
    adjacent = cost < tau
    return bool(np.any(adjacent.reshape(-1, cost.shape[0] // P, P).sum(axis=2) >= 2))


def test_exact_matches_brute_force_on_tiny_scenes():
    competing = 0
    for xy, mask, _ in _tiny_scenes():
        d = np.asarray(distances(RIG3, jnp.asarray(xy), jnp.asarray(mask)))
        P = mask.shape[1]
        groups, valid, value = exact_groups(d, mask, TAU)
        cost = gated_cost(d, mask)
        nodes = [int(n) for n in np.flatnonzero(mask.reshape(-1))]
        want, partition = _brute_force(cost, nodes, TAU)
        found = _sets(groups, valid, P)
        assert value == pytest.approx(want, abs=1e-6)
        assert sum(clique_cost(cost, g, TAU) for g in found) == pytest.approx(want, abs=1e-6)
        assert all(len({n // P for n in g}) == len(g) for g in found)
        if found != set(partition):  # another optimum: it must cost exactly as much
            assert sum(clique_cost(cost, g, TAU) for g in partition) == pytest.approx(
                value, abs=1e-6
            )
        competing += _competing(cost, TAU, P)
    assert competing >= 5, "too few scenes with competing cliques: the check says little"


def _labels_to_sets(labels, mask):
    P = mask.shape[1]
    groups = {}
    for m, i in zip(*np.nonzero((np.asarray(labels) >= 0) & mask)):
        groups.setdefault(int(labels[m, i]), set()).add(int(m) * P + int(i))
    return [frozenset(g) for g in groups.values()]


def test_exact_is_never_worse_than_greedy_or_voting():
    scenes = _tiny_scenes()
    xy, mask = np.stack([s[0] for s in scenes]), np.stack([s[1] for s in scenes])
    compared = 0
    for name in ("greedy", "voting"):
        other = associate_batch(RIG3, xy, mask, method=name, sigma=SIGMA)
        for b in range(len(scenes)):
            d = np.asarray(distances(RIG3, jnp.asarray(xy[b]), jnp.asarray(mask[b])))
            cost = gated_cost(d, mask[b])
            _, _, best = exact_groups(d, mask[b], TAU)
            theirs = _labels_to_sets(other.labels[b], mask[b])
            if all(
                all(cost[a, c] < TAU for a, c in itertools.combinations(sorted(g), 2))
                for g in theirs
            ):
                compared += 1
                assert best <= sum(clique_cost(cost, g, TAU) for g in theirs) + 1e-6, (name, b)
    assert compared >= len(scenes), "too few comparable scenes"


def test_exact_refuses_large_scenes_and_tracing():
    rig = ring_rig(3)
    xy, mask, _, _ = random_scene(rig, MAX_POINTS + 1, MAX_POINTS + 1, sigma=0.0, seed=1)
    with pytest.raises(ValueError, match=f"at most {MAX_POINTS} points.*view"):
        associate(rig, xy, mask, method="exact", sigma=0.0)
    small = mask & (np.arange(mask.shape[1]) < 4)[None, :]
    with pytest.raises(ValueError, match="scene 1"):  # before scene 0 is associated
        associate_batch(rig, np.stack([xy, xy]), np.stack([small, mask]), method="exact", sigma=0.0)
    method = Exact()
    thresholds = method.thresholds(1.0)
    from cdog_jax import Observations

    with pytest.raises(TypeError, match="host method"):
        jax.jit(lambda x, m: method.associate_scene(rig, Observations(x, m), thresholds))(
            jnp.asarray(xy), jnp.asarray(mask)
        )


def test_sweep_refuses_a_host_method():
    with pytest.raises(ValueError, match="runs on the host.*sweep_host"):
        sweep(
            RIG3,
            Grid(sigmas=(0.0,), counts=(3,), scenes=1),
            methods=["exact"],
            timing=False,
            progress=False,
        )


def test_exact_with_weights_and_min_views_is_finished_like_every_method():
    rig = ring_rig(4)
    xy, mask, _, _ = random_scene(rig, 6, 8, sigma=1.0, seed=3)
    plain = associate(rig, xy, mask, method="exact", sigma=1.0)
    weighted = associate(
        rig, xy, mask, method="exact", sigma=1.0, weights=np.ones(mask.shape, np.float32)
    )
    np.testing.assert_array_equal(weighted.labels, plain.labels)
    three = associate(rig, xy, mask, method="exact", sigma=1.0, min_views=3)
    keep = np.asarray(plain.n_views)[np.asarray(plain.valid)] >= 3
    assert 0 < keep.sum() < np.asarray(plain.valid).sum()
    assert int(three.num_groups) == int(keep.sum()) and np.all(
        np.asarray(three.n_views)[np.asarray(three.valid)] >= 3
    )


def test_robust_sigma_of_a_group_table_method_is_c_dogs_robust_estimate():
    """``sigma_mode="robust"`` gives a baseline, jitted or on the host, the σ of C-DOG's
    robust estimator on the same scene; an unknown mode is refused with the choices."""
    from cdog_jax import Config
    from cdog_jax.baselines import Greedy

    rig = ring_rig(4)
    xy, mask, _, _ = random_scene(rig, 12, 12, sigma=2.0, seed=5)
    xy = xy.astype(np.float32)
    ours = associate(rig, xy, mask, method=Config.extended(sigma_mode="robust"), sigma="auto")
    for method in (Greedy(sigma_mode="robust"), Exact(sigma_mode="robust")):
        result = associate(rig, xy, mask, method=method, sigma="auto")
        np.testing.assert_allclose(float(result.sigma_px), float(ours.sigma_px), rtol=1e-6)
    auto = associate(rig, xy, mask, method=Exact(sigma_mode="auto"), sigma="auto")
    assert float(auto.sigma_px) != float(ours.sigma_px)
    with pytest.raises(ValueError, match="sigma_mode must be one of.*robust"):
        Exact(sigma_mode="median")
