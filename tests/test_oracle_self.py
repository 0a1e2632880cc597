"""Tests of the NumPy oracle (tests/oracle.py) on its own; no JAX pipeline needed."""

import itertools

import numpy as np
import pytest
from oracle import (
    adjacency,
    bpe_jump_keep,
    components,
    directed_edges,
    epipolar_distance_table,
    estimate_sigma,
    focal_scale,
    fundamental_matrices,
    iqr_outliers,
    iqr_scores,
    look_at,
    make_rig,
    make_scene,
    oracle_associate,
    overlap_theta,
    project,
    second_association,
    split_view_unique,
    triangulate_dlt,
    triangulate_dlt_svd,
)

from cdog_jax import Config


def hand_rig():
    """5 cameras ~3 units from the unit box; view 1 has K multiplied by -1 (K[2,2] = -1)."""
    centers = [(3, 0, 1), (0, 3, 0.5), (-3, 0.3, 1.2), (0.2, -3, 0.8), (2, 2, 1.5)]
    K0 = np.array([[500.0, 0.5, 320.0], [0.0, 510.0, 240.0], [0.0, 0.0, 1.0]])
    K, R, t = [], [], []
    for m, c in enumerate(centers):
        Rm, tm = look_at(c)
        K.append(-K0 if m == 1 else K0 * (1 + 0.05 * m) + np.diag([0, 0, -0.05 * m]))
        R.append(Rm)
        t.append(tm)
    return np.array(K), np.array(R), np.array(t)


def assert_consistent(res, mask):
    """Invariants of an Association-like dict."""
    M, P = mask.shape
    G = M * P // 2
    k = res["num_groups"]
    assert res["groups"].shape == (G, M) and res["valid"].shape == (G,)
    assert res["valid"][:k].all() and not res["valid"][k:].any()
    assert (res["groups"][k:] == -1).all()
    assert (res["n_views"][:k] >= 2).all()
    assert (res["n_views"] == (res["groups"] >= 0).sum(1)).all()
    labels = np.full((M, P), -1)
    for g in range(k):
        for m in range(M):
            if res["groups"][g, m] >= 0:
                assert mask[m, res["groups"][g, m]]
                labels[m, res["groups"][g, m]] = g
    np.testing.assert_array_equal(labels, res["labels"])
    assert np.isfinite(res["points3d"][:k]).all() and np.isfinite(res["bpe"][:k]).all()
    assert res["tau_px"] >= 0 and res["sigma_px"] >= 0


# ----------------------------------------------------------------------------- geometry


def test_fundamental_matrices_on_exact_projections():
    K, R, t = hand_rig()
    assert K[1, 2, 2] == -1.0
    rng = np.random.default_rng(0)
    X = rng.uniform(-0.5, 0.5, (20, 3))
    xy = np.stack([project(K, R, t, x) for x in X], axis=1)  # (M, 20, 2)
    h = np.concatenate([xy, np.ones(xy.shape[:2] + (1,))], -1)
    F = fundamental_matrices(K, R, t)
    M = K.shape[0]
    for m, n in itertools.permutations(range(M), 2):
        np.testing.assert_allclose(np.linalg.norm(F[m, n]), 1.0)
        r = np.einsum("pi,ij,pj->p", h[n], F[m, n], h[m])
        assert np.abs(r).max() < 1e-9, (m, n)
        # the same pair the other way round is the transpose, up to sign
        s = np.sign(np.sum(F[n, m] * F[m, n].T))
        np.testing.assert_allclose(F[n, m], s * F[m, n].T, atol=1e-12)
    # the distance table is ~0 on true correspondences
    d = epipolar_distance_table(K, R, t, xy, np.ones(xy.shape[:2], bool))
    for m, n in itertools.permutations(range(M), 2):
        assert np.diagonal(d[m, :, n, :]).max() < 1e-8
    assert np.isinf(d[np.arange(M), :, np.arange(M), :]).all()


def test_epipolar_distance_table_literal():
    K, R, t = hand_rig()
    rng = np.random.default_rng(1)
    M, P = K.shape[0], 4
    xy = rng.uniform(0, 600, (M, P, 2))
    mask = rng.uniform(size=(M, P)) < 0.7
    mask[:, 0] = True
    d = epipolar_distance_table(K, R, t, xy, mask)
    F = fundamental_matrices(K, R, t)
    for m, i, n, j in itertools.product(range(M), range(P), range(M), range(P)):
        if m == n or not (mask[m, i] and mask[n, j]):
            assert d[m, i, n, j] == np.inf
            continue
        line = F[m, n] @ np.append(xy[m, i], 1.0)
        expected = abs(line @ np.append(xy[n, j], 1.0)) / np.hypot(line[0], line[1])
        np.testing.assert_allclose(d[m, i, n, j], expected, rtol=1e-12)


def test_dlt_exact_on_noise_free_points():
    K, R, t = hand_rig()
    rng = np.random.default_rng(2)
    M = K.shape[0]
    for X in rng.uniform(-0.5, 0.5, (10, 3)):
        xy = project(K, R, t, X)
        for views in [(0, 1), (1, 3), (0, 2, 4), tuple(range(M))]:
            use = np.zeros(M, bool)
            use[list(views)] = True
            np.testing.assert_allclose(triangulate_dlt(K, R, t, xy, use), X, atol=1e-10)
            np.testing.assert_allclose(triangulate_dlt_svd(K, R, t, xy, use), X, atol=1e-10)
            # the origin shift c̄ does not change the solution
            np.testing.assert_allclose(
                triangulate_dlt(K, R, t, xy, use, center=np.zeros(3)), X, atol=1e-10
            )


def test_dlt_noisy_close_to_svd():
    K, R, t = hand_rig()
    rng = np.random.default_rng(3)
    use = np.ones(K.shape[0], bool)
    for X in rng.uniform(-0.5, 0.5, (10, 3)):
        xy = project(K, R, t, X) + rng.normal(0, 1.0, (K.shape[0], 2))
        a = triangulate_dlt(K, R, t, xy, use)
        b = triangulate_dlt_svd(K, R, t, xy, use)
        assert np.linalg.norm(a - X) < 0.02 and np.linalg.norm(a - b) < 0.01


# ----------------------------------------------------------------------------- graph


def test_overlap_theta_by_hand():
    # triangle 0-1-2 plus pendant 2-3
    A = np.zeros((4, 4), bool)
    for u, v in [(0, 1), (1, 2), (0, 2), (2, 3)]:
        A[u, v] = A[v, u] = True
    thresholds = overlap_theta(A)
    # closed neighbourhoods: N0 = {0,1,2}, N1 = {0,1,2}, N2 = {0,1,2,3}, N3 = {2,3}
    np.testing.assert_allclose(thresholds[0, 1], 3 / 3)
    np.testing.assert_allclose(thresholds[0, 2], 3 / 4)
    np.testing.assert_allclose(thresholds[2, 3], 2 / 4)
    assert thresholds[0, 3] == 0 and thresholds[1, 3] == 0
    np.testing.assert_allclose(thresholds, thresholds.T)


def test_components_smallest_index():
    A = np.zeros((7, 7), bool)
    for u, v in [(5, 1), (1, 3), (6, 4)]:
        A[u, v] = A[v, u] = True
    np.testing.assert_array_equal(components(A), [0, 1, 2, 1, 4, 1, 4])


def test_directed_edges_ties_and_gate():
    M, P = 2, 3
    d = np.full((M, P, M, P), np.inf)
    mask = np.ones((M, P), bool)
    d[0, 0, 1] = [0.5, 0.2, 0.2]  # tie: smallest j
    d[0, 1, 1] = [3.0, 4.0, 5.0]  # above tau
    d[1, 1, 0] = [0.1, 0.3, 0.0]
    out = directed_edges(d, mask, tau=1.0)
    assert out[0, 1] == 1 * P + 1
    assert out[1, 1] == -1
    assert out[1 * P + 1, 0] == 2
    A = adjacency(d, mask, 1.0, "mutual")
    assert not A.any()  # (0,0)→(1,1) but (1,1)→(0,2)
    U = adjacency(d, mask, 1.0, "union")
    assert U[0, 4] and U[4, 0] and U[2, 4] and U.sum() == 4


def test_split_weakest_edge_then_last_resort():
    # M = 2 views, P = 2: nodes 0, 1 (view 0) and 2, 3 (view 1); path 0 - 2 - 1 - 3
    M, P = 2, 2
    A = np.zeros((4, 4), bool)
    for u, v in [(0, 2), (2, 1), (1, 3)]:
        A[u, v] = A[v, u] = True
    theta = overlap_theta(A)
    e = np.full((4, 4), 1.0)
    e[1, 2] = e[2, 1] = 5.0
    # θ(0,2) = 2/3, θ(1,2) = 2/3, θ(1,3) = 2/3: ties broken by the largest e → cut 1-2
    A2, labels = split_view_unique(A, theta, e, M, P, max_iters=8)
    assert not A2[1, 2] and A2[0, 2] and A2[1, 3]
    np.testing.assert_array_equal(labels, [0, 1, 0, 1])
    # equal e as well: smallest (min, max) pair (0, 2) goes first; then (1, 3)? no: after
    # cutting 0-2, the component {1, 2, 3} still holds 2 and 3 of view 1 → cut (1, 2)
    e = np.ones((4, 4))
    A2, labels = split_view_unique(A, theta, e, M, P, max_iters=8)
    assert not A2[0, 2] and not A2[1, 2] and A2[1, 3]
    # one iteration only: the last resort detaches, per view, all but the node of the
    # smallest mean e over its current edges
    A2, labels = split_view_unique(A, theta, e, M, P, max_iters=1)
    # after cutting 0-2: component {1, 2, 3}, view 1 holds 2 (mean e 1) and 3 (mean e 1):
    # keep the smaller index 2, detach 3
    np.testing.assert_array_equal(labels, [0, 1, 1, 3])


# ----------------------------------------------------------------------------- IQR


def test_iqr_planted_outlier():
    K, R, t = hand_rig()
    M = K.shape[0]
    rng = np.random.default_rng(4)
    members = np.ones(M, bool)
    for _ in range(5):
        X = rng.uniform(-0.5, 0.5, 3)
        xy = project(K, R, t, X) + rng.normal(0, 0.3, (M, 2))
        bad = rng.integers(M)
        xy[bad] += rng.choice([-1, 1], 2) * 40.0
        for score, quart in [("exclude_own", "zero_pad"), ("include_own", "positive")]:
            s = iqr_scores(K, R, t, xy, members, score)
            assert np.argmax(s) == bad
            out = iqr_outliers(s, members, 1.5, quart)
            assert out[bad]
            assert out.sum() == 1, (s, out)


def test_iqr_outliers_by_hand():
    members = np.array([True, True, True, True, True, False])
    s = np.array([1.0, 1.2, 0.9, 1.1, 10.0, 99.0])
    # zero_pad: values [1, 1.2, .9, 1.1, 10, 0] → Q1 = 0.925, Q3 = 1.175, IQR = 0.25
    q1, q3 = np.percentile([1, 1.2, 0.9, 1.1, 10, 0], [25, 75])
    assert np.isclose(q1, 0.925) and np.isclose(q3, 1.175)
    np.testing.assert_array_equal(iqr_outliers(s, members, 2.0, "zero_pad"), [0, 0, 0, 0, 1, 0])
    # positive: values [1, 1.2, .9, 1.1, 10] → Q1 = 1, Q3 = 1.2, ub = 1.6
    np.testing.assert_array_equal(iqr_outliers(s, members, 2.0, "positive"), [0, 0, 0, 0, 1, 0])
    # a low score below lb = max(0, Q1 − α IQR) is an outlier too
    s0 = np.array([0.1, 5.0, 5.1, 5.2, 5.05, 0.0])
    np.testing.assert_array_equal(iqr_outliers(s0, members, 1.5, "positive"), [1, 0, 0, 0, 0, 0])
    # ... but never a zero score (an outlier's score must exceed the floor, ≥ 0)
    np.testing.assert_array_equal(
        iqr_outliers(np.where(s0 == 0.1, 0.0, s0), members, 1.5, "positive"), [0] * 6
    )
    # the absolute floor: an outlier's score must also exceed it (either side of the fences)
    np.testing.assert_array_equal(iqr_outliers(s, members, 2.0, "zero_pad", floor_px=10.0), [0] * 6)
    np.testing.assert_array_equal(iqr_outliers(s0, members, 1.5, "positive", floor_px=1.0), [0] * 6)
    tiny = np.array([1e-13, 2e-13, 1.5e-13, 9e-13, 1.2e-13, 0.0])
    np.testing.assert_array_equal(iqr_outliers(tiny, members, 2.0, "zero_pad"), [0, 0, 0, 1, 0, 0])
    assert not iqr_outliers(tiny, members, 2.0, "zero_pad", floor_px=1.0).any()
    # no positive score → no outlier
    assert not iqr_outliers(np.zeros(6), members, 1.5, "positive").any()
    # guards: everything below 10 px → no outlier at all
    assert not iqr_outliers(s, members, 2.0, "zero_pad", guards=True, min_px=10.5).any()
    # guards: no fence outlier but the max is above 50 px → the max goes (ties: lowest view)
    s2 = np.array([60.0, 60.0, 55.0, 58.0, 59.0, 0.0])
    assert not iqr_outliers(s2, members, 2.0, "positive").any()
    np.testing.assert_array_equal(
        iqr_outliers(s2, members, 2.0, "positive", guards=True), [1, 0, 0, 0, 0, 0]
    )


# ----------------------------------------------------------------------------- §7, §8


def test_second_association_by_hand():
    M, P = 3, 3
    mask = np.ones((M, P), bool)
    d = np.full((M, P, M, P), 100.0)
    groups = np.full((4, M), -1)
    gvalid = np.array([True, True, False, False])
    groups[0] = [0, 0, -1]
    groups[1] = [1, 1, -1]
    # leftover (2,0): cost to g0 = mean(1, 1) = 1, to g1 = mean(2, 2) = 2 → g0
    d[0, 0, 2, 0] = d[1, 0, 2, 0] = 1.0
    d[0, 1, 2, 0] = d[1, 1, 2, 0] = 2.0
    # leftover (2,1): cost to g0 = 0.5 → also g0 and wins (smaller cost)
    d[0, 0, 2, 1] = d[1, 0, 2, 1] = 0.5
    # leftover (2,2): cost to g1 = mean(1, w(12) = 36) = 18.5 ≥ 5, to g0 ≥ ...: stays out
    d[0, 1, 2, 2], d[1, 1, 2, 2] = 1.0, 12.0
    # leftover (0,2): can only join a group lacking view 0: none
    new = second_association(groups, gvalid, d, mask, tau=10.0, frac=0.5)
    np.testing.assert_array_equal(new[0], [0, 0, 1])
    np.testing.assert_array_equal(new[1], [1, 1, -1])
    # with the 3x weight removed (larger tau) (2,2) joins g1 at cost 6.5 < 0.5 * 13.5
    new = second_association(groups, gvalid, d, mask, tau=13.5, frac=0.5)
    np.testing.assert_array_equal(new[1], [1, 1, 2])


def test_bpe_jump_keep_by_hand():
    bpe = np.array([0.3, 0.1, 100.0, 0.2, 0.35, 0.5, 120.0, 0.0])
    valid = np.array([1, 1, 1, 1, 1, 1, 1, 0], bool)
    # sorted: .1 .2 .3 .35 .5 100 120; gaps .1 .1 .05 .15 99.5 20 → jump at i = 4
    keep = bpe_jump_keep(
        bpe, valid, kappa=10.0, floor_px2=4.0, floor_sigma=3.0, sigma=0.0, min_gaps=3
    )
    np.testing.assert_array_equal(keep, [1, 1, 0, 1, 1, 1, 0, 0])
    # floor above the gap → no jump
    keep = bpe_jump_keep(
        bpe, valid, kappa=10.0, floor_px2=4.0, floor_sigma=3.0, sigma=4.0, min_gaps=3
    )
    np.testing.assert_array_equal(keep, valid)
    # too few gaps before i = 4 → the next gap (20 > 10 · median(.1 .1 .05 .15 99.5)) jumps
    keep = bpe_jump_keep(
        bpe, valid, kappa=10.0, floor_px2=4.0, floor_sigma=3.0, sigma=0.0, min_gaps=5
    )
    np.testing.assert_array_equal(keep, [1, 1, 1, 1, 1, 1, 0, 0])
    keep = bpe_jump_keep(
        bpe, valid, kappa=10.0, floor_px2=4.0, floor_sigma=3.0, sigma=0.0, min_gaps=6
    )
    np.testing.assert_array_equal(keep, valid)
    # ties in BPE are sorted by group id; the first gap counting is i ≥ min_gaps
    bpe2 = np.array([1.0, 1.0, 1.0, 1.0, 50.0])
    keep = bpe_jump_keep(
        bpe2, np.ones(5, bool), kappa=10.0, floor_px2=4.0, floor_sigma=0.0, sigma=0.0, min_gaps=3
    )
    np.testing.assert_array_equal(keep, [1, 1, 1, 1, 0])  # median of zeros = 0


def test_estimate_sigma_ballpark():
    rng = np.random.default_rng(5)
    K, R, t = make_rig(6, rng)
    for sigma in (1.0, 2.0):
        xy, mask, _, _ = make_scene(K, R, t, 30, rng, sigma=sigma, drop=0.3, clutter=3)
        d = epipolar_distance_table(K, R, t, xy, mask)
        est, fallback = estimate_sigma(d, mask, focal_scale(K))
        assert 0.5 * sigma < est < 1.5 * sigma and not fallback
    assert estimate_sigma(np.full((2, 1, 2, 1), np.inf), np.zeros((2, 1), bool), 1000.0) == (
        1.0,
        True,
    )


# ----------------------------------------------------------------------------- whole pipeline


def _purity(res, inst):
    """Whether every group is one instance, and the set of instances that got a group."""
    M = inst.shape[0]
    pure, got = True, set()
    for g in range(res["num_groups"]):
        ids = {int(inst[m, res["groups"][g, m]]) for m in range(M) if res["groups"][g, m] >= 0}
        pure &= len(ids) == 1 and -1 not in ids
        got |= ids
    return pure, got


@pytest.mark.parametrize("seed", range(8))
def test_noise_free_scenes_perfect(seed):
    """σ = 0, every point in every view, shuffled slots: one group per point with all views,
    for both presets (the paper's IQR has a 1 px floor, the reference's the 10 px guard)."""
    rng = np.random.default_rng(100 + seed)
    M = int(rng.integers(4, 7))
    K, R, t = make_rig(M, rng, negative_k=(seed % M,))
    n = int(rng.integers(5, 16))
    xy, mask, inst, X = make_scene(K, R, t, n, rng, sigma=0.0)
    for cfg in (Config.paper(), Config.paper(iqr=False), Config.reference()):
        res = oracle_associate(K, R, t, xy, mask, cfg, sigma=0.0)
        assert_consistent(res, mask)
        assert res["num_groups"] == n
        assert (res["n_views"][:n] == M).all()
        pure, got = _purity(res, inst)
        assert pure and got == set(range(n))
        for g in range(n):
            p = inst[0, res["groups"][g, 0]]
            np.testing.assert_allclose(res["points3d"][g], X[p], atol=1e-9)
            assert res["bpe"][g] < 1e-16


def test_noise_free_iqr_without_floor_drops_roundoff_nodes():
    """Why §6 has ``iqr_floor_px``: at σ = 0 the scores are round-off (~1e-13 px) and the
    fences alone make outliers of perfect nodes; groups stay pure."""
    rng = np.random.default_rng(0)
    dropped = 0
    for _ in range(10):
        M = int(rng.integers(4, 7))
        K, R, t = make_rig(M, rng)
        xy, mask, inst, _ = make_scene(K, R, t, int(rng.integers(5, 16)), rng, sigma=0.0)
        res = oracle_associate(K, R, t, xy, mask, Config.paper(iqr_floor_px=0.0), sigma=0.0)
        assert _purity(res, inst)[0]
        dropped += int((res["n_views"][: res["num_groups"]] < M).sum())
    assert dropped > 0


BRANCHES = {
    "paper": Config.paper(),
    "reference": Config.reference(),
    "union": Config.paper(adjacency="union"),
    "prune_conflicts": Config.paper(prune_scope="conflicts"),
    "prune_none": Config.paper(prune_scope="none"),
    "no_iqr": Config.paper(iqr=False),
    "iqr_include_own": Config.paper(iqr_score="include_own"),
    "iqr_positive": Config.paper(iqr_quartiles="positive"),
    "iqr_guards": Config.paper(iqr_guards=True),
    "second_assoc": Config.paper(second_association=True),
    "no_bpe": Config.paper(bpe_filter=False),
    "ref_with_bpe": Config.reference(bpe_filter=True),
    "auto": Config.paper(sigma_mode="auto"),
    "split_1": Config.paper(max_split_iters=1, prune_scope="none", adjacency="union"),
    "iqr_1": Config.paper(max_iqr_iters=1),
    "iqr_no_floor": Config.paper(iqr_floor_px=0.0),
    "jump_min_gaps_1": Config.paper(jump_min_gaps=1),
}


@pytest.mark.parametrize("name", sorted(BRANCHES))
def test_branches_run(name):
    cfg = BRANCHES[name]
    rng = np.random.default_rng(7)
    K, R, t = make_rig(5, rng)
    for sigma in (0.5, 3.0):
        xy, mask, inst, _ = make_scene(K, R, t, 12, rng, sigma=sigma, P=16, drop=0.25, clutter=2)
        res = oracle_associate(K, R, t, xy, mask, cfg, sigma="auto" if name == "auto" else sigma)
        assert_consistent(res, mask)
        assert res["num_groups"] > 0
        if name == "auto":
            assert 0.2 * sigma < res["sigma_px"] < 3 * sigma


def test_refine_not_implemented():
    rng = np.random.default_rng(8)
    K, R, t = make_rig(3, rng)
    xy, mask, _, _ = make_scene(K, R, t, 3, rng)
    with pytest.raises(NotImplementedError):
        oracle_associate(K, R, t, xy, mask, Config.paper(refine=True), sigma=1.0)


def test_padding_garbage_ignored():
    rng = np.random.default_rng(9)
    K, R, t = make_rig(4, rng)
    xy, mask, _, _ = make_scene(K, R, t, 8, rng, sigma=1.0, P=12, drop=0.2, clutter=1)
    ref = oracle_associate(K, R, t, xy, mask, Config.paper(), sigma=1.0)
    xy2 = np.where(mask[..., None], xy, rng.uniform(-1e3, 1e3, xy.shape))
    res = oracle_associate(K, R, t, xy2, mask, Config.paper(), sigma=1.0)
    for key in ("labels", "groups", "valid", "n_views"):
        np.testing.assert_array_equal(res[key], ref[key])
    np.testing.assert_allclose(res["points3d"], ref["points3d"])


def test_noisy_scenes_mostly_right():
    """At σ = 1 the paper preset recovers most points in pure groups."""
    rng = np.random.default_rng(10)
    K, R, t = make_rig(6, rng)
    xy, mask, inst, _ = make_scene(K, R, t, 15, rng, sigma=1.0, drop=0.2)
    res = oracle_associate(K, R, t, xy, mask, Config.paper(), sigma=1.0)
    pure_groups = 0
    for g in range(res["num_groups"]):
        ids = {int(inst[m, res["groups"][g, m]]) for m in range(6) if res["groups"][g, m] >= 0}
        pure_groups += len(ids) == 1
    assert pure_groups >= 12
