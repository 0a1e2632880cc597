"""docs/BENCHMARK.md §2 metrics: a plain NumPy reference written from the text, hand-built cases, jit/vmap."""

import dataclasses
import functools
from collections import Counter

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cdog_jax._result import Association
from cdog_jax.geometry._camera import Rig
from cdog_jax.metrics import Metrics, mean_metrics, scene_metrics
from cdog_jax.synthetic._scene import Scene

FIELDS = ("g_p", "g_r", "g_f1", "g_iou", "mp_p", "mp_r", "mp_f1", "mp_iou", "pg_p", "pg_r", "pg_f1")
COUNTS = ("num_pred_groups", "num_gt_groups", "num_unassigned", "num_err_groups", "has_groups")
KMAT = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])


# --------------------------------------------------------------------------- builders


def make_rig(M=4, dist=3.0):
    """M cameras on a circle (slightly above the xy plane) looking at the origin."""
    K, R, t = [], [], []
    for m in range(M):
        a = 2 * np.pi * m / M
        C = dist * np.array([np.cos(a), np.sin(a), 0.3]) / np.linalg.norm([1.0, 0.0, 0.3])
        z = -C / np.linalg.norm(C)
        x = np.cross(z, [0.0, 0.0, 1.0])
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        Rm = np.stack([x, y, z])
        K.append(KMAT)
        R.append(Rm)
        t.append(-Rm @ C)
    return Rig(*(jnp.asarray(np.stack(a), jnp.float32) for a in (K, R, t)))


def np_project(rig, X):
    """(M, 2) pixels of one world point, in float64."""
    K, R, t = (np.asarray(a, np.float64) for a in (rig.K, rig.R, rig.t))
    h = np.einsum("mij,mj->mi", K, np.einsum("mij,j->mi", R, X) + t)
    return h[:, :2] / h[:, 2:]


def make_scene(instance, mask, gt_points):
    """Scene from an (M, P) instance table (-1: clutter where mask, padding elsewhere)."""
    M, P = instance.shape
    xy = np.zeros((M, P, 2), np.float32)
    pts = np.zeros((P, 3), np.float32)
    pts[: len(gt_points)] = gt_points
    return Scene(
        xy=jnp.asarray(xy),
        mask=jnp.asarray(mask, bool),
        instance=jnp.asarray(np.where(mask, instance, -1), jnp.int32),
        points3d=jnp.asarray(pts),
        num_points=jnp.asarray(len(gt_points), jnp.int32),
    )


def make_assoc(labels, points3d=None, valid=None):
    """Association with groups/valid/points3d consistent with (M, P) labels, G = M*P//2."""
    labels = np.asarray(labels, np.int32)
    M, P = labels.shape
    G = max(M * P // 2, 1)
    groups = -np.ones((G, M), np.int32)
    for m in range(M):
        for i in range(P):
            if labels[m, i] >= 0:
                groups[labels[m, i], m] = i
    if valid is None:
        valid = (groups >= 0).any(axis=1)
    pts = np.zeros((G, 3), np.float32) if points3d is None else np.asarray(points3d, np.float32)
    n_views = (groups >= 0).sum(axis=1).astype(np.int32)
    return Association(
        labels=jnp.asarray(labels),
        groups=jnp.asarray(groups),
        valid=jnp.asarray(valid, bool),
        points3d=jnp.asarray(pts),
        bpe=jnp.zeros((G,), jnp.float32),
        err_px=jnp.zeros((G,), jnp.float32),
        n_views=jnp.asarray(n_views),
        num_groups=jnp.asarray(int(np.sum(valid)), jnp.int32),
        sigma_px=jnp.asarray(0.0, jnp.float32),
        tau_px=jnp.asarray(0.0, jnp.float32),
        status=jnp.int32(0),
    )


def random_case(rng, M, P):
    """A random scene (shuffled slots, clutter, padding) and a perturbed-truth prediction."""
    G = max(M * P // 2, 1)
    n = int(rng.integers(0, min(P, G) + 1))
    gt_points = rng.uniform(-0.5, 0.5, (n, 3))
    instance = -np.ones((M, P), np.int64)
    mask = np.zeros((M, P), bool)
    for m in range(M):
        ids = [k for k in range(n) if rng.random() < 0.7]
        ids += [-1] * int(rng.integers(0, 3))  # clutter
        ids = ids[:P]
        slots = rng.permutation(P)[: len(ids)]
        instance[m, slots] = rng.permutation(ids)
        mask[m, slots] = True
    # Perturbed truth: instance k -> group perm[k]; drop, swap and attach clutter at random.
    perm = rng.permutation(G)
    p_drop, p_swap = rng.uniform(0, 0.4), rng.uniform(0, 0.4)
    labels = -np.ones((M, P), np.int64)
    for m, i in zip(*np.nonzero(mask)):
        r = rng.random()
        if instance[m, i] >= 0 and r > p_drop + p_swap:
            labels[m, i] = perm[instance[m, i]]
        elif r > p_drop:
            labels[m, i] = rng.integers(0, G)
    if rng.random() < 0.3:  # merge two groups
        a, b = rng.integers(0, G, 2)
        labels[labels == a] = b
    valid = np.zeros(G, bool)
    valid[labels[labels >= 0]] = True
    if (
        rng.random() < 0.3
    ):  # a valid group without members, and a label pointing at an invalid group
        valid[rng.integers(0, G)] = True
        valid[rng.integers(0, G)] = False
    points3d = rng.uniform(-0.6, 0.6, (G, 3))
    for g in range(G):
        members = instance[(labels == g) & (instance >= 0)]
        if len(members) and rng.random() < 0.8:
            points3d[g] = gt_points[members[0]] + rng.normal(0, 0.02, 3)
    return make_scene(instance, mask, gt_points), make_assoc(labels, points3d, valid)


def stack(trees):
    """A batch of pytrees (on the host: stacking device arrays would compile per shape)."""
    return jax.tree.map(lambda *xs: np.stack(xs), *trees)


def unstack(tree, b):
    return jax.tree.map(lambda x: np.asarray(x)[b], tree)


@functools.cache
def random_batch(M, P, B=48):
    """B random (scene, association) pairs and their metrics from jit(vmap(scene_metrics))."""
    rng = np.random.default_rng(M * 100 + P)
    cases = [random_case(rng, M, P) for _ in range(B)]
    out = batched_metrics(make_rig(M), stack([a for _, a in cases]), stack([s for s, _ in cases]))
    return cases, jax.device_get(out)


# --------------------------------------------------------------------------- reference


def div(a, b):
    return a / b if b else 0.0


def hmean(p, r):
    return div(2 * p * r, p + r)


def reference_metrics(rig, result, scene):
    """docs/BENCHMARK.md §2 with Python loops over nodes and groups, float64."""
    labels, valid = np.asarray(result.labels), np.asarray(result.valid)
    X_hat = np.asarray(result.points3d, np.float64)
    mask, instance = np.asarray(scene.mask), np.asarray(scene.instance)
    X_gt = np.asarray(scene.points3d, np.float64)
    M, P = mask.shape
    G = len(valid)
    nodes = [(m, i) for m in range(M) for i in range(P) if mask[m, i]]

    # Predicted groups: valid groups, then unassigned valid nodes as singletons G + u.
    pred = {}
    for m, i in nodes:
        lab = labels[m, i]
        pid = lab if 0 <= lab < G and valid[lab] else G + m * P + i
        pred.setdefault(pid, []).append((m, i))
    gt_size = Counter(instance[n] for n in nodes if instance[n] >= 0)
    gt_groups = {k for k, c in gt_size.items() if c >= 2}

    def majority(members):
        cnt = Counter(int(instance[n]) for n in members)  # clutter votes -1
        best = max(cnt.values())
        g = min(k for k, c in cnt.items() if c == best)
        return g, (cnt[g] if g >= 0 else 0)

    # G-: candidates per instance; each instance takes the group holding most of its nodes.
    cands = {}
    for pid in sorted(pred):
        g, k = majority(pred[pid])
        if g >= 0 and k >= 2 and k > len(pred[pid]) / 2:
            cands.setdefault(g, []).append((k, pid))
    matches = {g: min(c, key=lambda kp: (-kp[0], kp[1]))[1] for g, c in cands.items()}
    tp = len(matches)
    fp, fn = len(pred) - tp, len(gt_groups) - tp
    out = {"g_p": div(tp, tp + fp), "g_r": div(tp, tp + fn)}
    out["g_f1"] = hmean(out["g_p"], out["g_r"])
    out["g_iou"] = div(tp, tp + fp + fn)

    multi = [pid for pid in sorted(pred) if len(pred[pid]) >= 2]
    scores, perfect, errs, bpes = [], set(), [], []
    for pid in multi:
        members = pred[pid]
        g, k = majority(members)
        tp_p, fp_p = k, len(members) - k
        fn_p = gt_size[g] - k if g >= 0 else 0
        p, r = div(tp_p, tp_p + fp_p), div(tp_p, tp_p + fn_p)
        scores.append((p, r, hmean(p, r), div(tp_p, tp_p + fp_p + fn_p)))
        if g >= 0 and all(instance[n] == g for n in members):
            perfect.add(g)
        if g >= 0:
            errs.append(np.linalg.norm(X_hat[pid] - X_gt[g]))
            views = sorted({m for m, i in nodes if instance[m, i] == g})
            d = np.linalg.norm(np_project(rig, X_hat[pid]) - np_project(rig, X_gt[g]), axis=1)
            bpes.append(np.mean(d[views]))
    means = np.mean(scores, axis=0) if scores else np.zeros(4)
    out.update(mp_p=means[0], mp_r=means[1], mp_f1=means[2], mp_iou=means[3])
    tp = len(perfect)
    fp, fn = len(multi) - tp, len(gt_groups) - tp
    out.update(pg_p=div(tp, tp + fp), pg_r=div(tp, tp + fn))
    out["pg_f1"] = hmean(out["pg_p"], out["pg_r"])
    out["err3d"] = np.mean(errs) if errs else 0.0
    out["bpe_px"] = np.mean(bpes) if bpes else 0.0
    out.update(
        num_pred_groups=len(multi),
        num_gt_groups=len(gt_groups),
        num_unassigned=sum(pid >= G for pid in pred),
        num_err_groups=len(errs),
        has_groups=len(multi) > 0,
    )
    return out


def assert_matches(metrics, ref, atol_px=2e-3):
    for k in FIELDS:
        np.testing.assert_allclose(
            float(getattr(metrics, k)), ref[k], rtol=1e-5, atol=1e-6, err_msg=k
        )
    for k in COUNTS:
        assert int(getattr(metrics, k)) == int(ref[k]), k
    np.testing.assert_allclose(
        float(metrics.err3d), ref["err3d"], rtol=1e-4, atol=1e-5, err_msg="err3d"
    )
    np.testing.assert_allclose(
        float(metrics.bpe_px), ref["bpe_px"], rtol=1e-4, atol=atol_px, err_msg="bpe_px"
    )


def assert_same(a, b):
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-5, atol=1e-6)


jit_metrics = jax.jit(scene_metrics)
batched_metrics = jax.jit(jax.vmap(scene_metrics, in_axes=(None, 0, 0)))


# --------------------------------------------------------------------------- tests


@pytest.mark.parametrize("M,P", [(4, 8), (3, 5), (2, 1)])
def test_random_against_reference(M, P):
    rig = make_rig(M)
    cases, out = random_batch(M, P)
    for b, (scene, assoc) in enumerate(cases):
        m = unstack(out, b)
        for leaf in jax.tree.leaves(m):
            assert np.all(np.isfinite(np.asarray(leaf, np.float64)))
        assert_matches(m, reference_metrics(rig, assoc, scene))


GT4 = np.array([[0.1, 0.0, 0.0], [0.0, 0.2, 0.0], [-0.1, 0.0, 0.1]])


@pytest.fixture
def three_points():
    """M=4, P=3: instances 0, 1, 2 each detected in three views, shuffled, one pad per view."""
    instance = np.array([[0, 1, -1], [1, 0, 2], [2, -1, 0], [-1, 1, 2]])
    mask = np.array([[1, 1, 0], [1, 1, 1], [1, 0, 1], [0, 1, 1]], bool)
    return make_scene(instance, mask, GT4), instance, mask


def test_perfect_association_scores_one(three_points):
    scene, instance, mask = three_points
    assoc = make_assoc(np.where(mask, instance, -1), np.pad(GT4, ((0, 3), (0, 0))))
    m = jit_metrics(make_rig(), assoc, scene)
    for k in FIELDS:
        assert float(getattr(m, k)) == pytest.approx(1.0), k
    assert float(m.err3d) == pytest.approx(0.0, abs=1e-6)
    assert float(m.bpe_px) == pytest.approx(0.0, abs=1e-3)
    assert (int(m.num_pred_groups), int(m.num_gt_groups), int(m.num_unassigned)) == (3, 3, 0)
    assert bool(m.has_groups)


def test_known_3d_and_pixel_errors(three_points):
    scene, instance, mask = three_points
    rig = make_rig()
    shift = np.array([0.03, -0.04, 0.0])
    assoc = make_assoc(np.where(mask, instance, -1), np.pad(GT4 + shift, ((0, 3), (0, 0))))
    m = jit_metrics(rig, assoc, scene)
    assert float(m.err3d) == pytest.approx(0.05, rel=1e-5)
    views = [[0, 1, 2], [0, 1, 3], [1, 2, 3]]  # where each instance is detected
    bpe = np.mean(
        [
            np.linalg.norm(np_project(rig, X + shift) - np_project(rig, X), axis=1)[v].mean()
            for X, v in zip(GT4, views)
        ]
    )
    assert bpe > 1.0
    assert float(m.bpe_px) == pytest.approx(bpe, rel=1e-4)


def test_everything_unassigned(three_points):
    scene, _, mask = three_points
    m = jit_metrics(make_rig(), make_assoc(-np.ones((4, 3), np.int32)), scene)
    for k in FIELDS + ("err3d", "bpe_px"):
        assert float(getattr(m, k)) == 0.0, k
    assert (int(m.num_pred_groups), int(m.num_gt_groups), int(m.num_unassigned)) == (
        0,
        3,
        int(mask.sum()),
    )
    assert not bool(m.has_groups)


def test_empty_scene_is_all_zero():
    scene = make_scene(-np.ones((3, 2), np.int64), np.zeros((3, 2), bool), GT4[:0])
    m = jit_metrics(make_rig(3), make_assoc(-np.ones((3, 2), np.int32)), scene)
    for leaf in jax.tree.leaves(m):
        assert float(leaf) == 0.0


def check(m, expected):
    for k, v in expected.items():
        assert float(getattr(m, k)) == pytest.approx(v, abs=1e-6), k


def column_case(instance, labels):
    """M=4, P=3: one valid detection per view in slot 0 (instance -1 is clutter)."""
    pad = -np.ones((4, 2), np.int64)
    mask = np.zeros((4, 3), bool)
    mask[:, 0] = True
    scene = make_scene(np.concatenate([np.array(instance)[:, None], pad], 1), mask, GT4)
    return scene, make_assoc(np.concatenate([np.array(labels)[:, None], pad], 1))


def test_merged_group_majority():
    # Instance 0 in views 0, 1, 2 and instance 1 in views 2, 3, all in one group.
    instance = np.array([[0, -1, -1], [0, -1, -1], [0, 1, -1], [1, -1, -1]])
    mask = instance >= 0
    scene = make_scene(instance, mask, GT4)
    m = jit_metrics(make_rig(), make_assoc(np.where(mask, 0, -1)), scene)
    check(m, dict(g_p=1, g_r=0.5, g_f1=2 / 3, g_iou=0.5, mp_p=0.6, mp_r=1, mp_f1=0.75, mp_iou=0.6))
    check(m, dict(pg_p=0, pg_r=0, pg_f1=0, num_pred_groups=1, num_gt_groups=2))


def test_merged_group_tie_does_not_match():
    scene, assoc = column_case([0, 0, 1, 1], [0, 0, 0, 0])
    m = jit_metrics(make_rig(), assoc, scene)
    check(
        m, dict(g_p=0, g_r=0, g_f1=0, g_iou=0, mp_p=0.5, mp_r=1, mp_f1=2 / 3, mp_iou=0.5, pg_f1=0)
    )


def test_duplicate_group_of_one_instance():
    scene, assoc = column_case([0, 0, 0, 0], [0, 0, 1, 1])
    m = jit_metrics(make_rig(), assoc, scene)
    check(m, dict(g_p=0.5, g_r=1, g_f1=2 / 3, g_iou=0.5, mp_p=1, mp_r=0.5, mp_f1=2 / 3, mp_iou=0.5))
    check(m, dict(pg_p=0.5, pg_r=1, pg_f1=2 / 3, num_pred_groups=2, num_gt_groups=1))


def test_clutter_in_a_group():
    scene, assoc = column_case([0, 0, 0, -1], [0, 0, 0, 0])  # view 3 holds clutter (mask True)
    m = jit_metrics(make_rig(), assoc, scene)
    check(m, dict(g_p=1, g_r=1, g_f1=1, g_iou=1, mp_p=0.75, mp_r=1, mp_f1=6 / 7, mp_iou=0.75))
    check(m, dict(pg_p=0, pg_r=0, pg_f1=0, num_err_groups=1))


def test_clutter_tie_votes_minus_one():
    # Group 0 = {instance 0, clutter}: g = -1, scores 0 and has no 3D error; group 1 is perfect.
    scene, assoc = column_case([0, -1, 1, 1], [0, 0, 1, 1])
    m = jit_metrics(make_rig(), assoc, scene)
    check(m, dict(g_p=0.5, g_r=1, g_iou=0.5, mp_p=0.5, mp_r=0.5, mp_f1=0.5, mp_iou=0.5))
    check(m, dict(pg_p=0.5, pg_r=1, num_pred_groups=2, num_gt_groups=1, num_err_groups=1))


def test_padding_garbage_changes_nothing():
    rng = np.random.default_rng(7)
    rig = make_rig()
    for _ in range(5):
        scene, assoc = random_case(rng, 4, 8)
        pad = ~np.asarray(scene.mask)
        G = assoc.valid.shape[0]
        junk_labels = np.where(pad, rng.integers(0, G, pad.shape), np.asarray(assoc.labels))
        junk_inst = np.where(pad, rng.integers(0, 8, pad.shape), np.asarray(scene.instance))
        junk_pts = np.where(np.asarray(assoc.valid)[:, None], np.asarray(assoc.points3d), np.nan)
        scene2 = Scene(
            xy=jnp.where(jnp.asarray(pad)[:, :, None], 1e6, scene.xy),
            mask=scene.mask,
            instance=jnp.asarray(junk_inst, jnp.int32),
            points3d=scene.points3d,
            num_points=scene.num_points,
        )
        assoc2 = make_assoc(junk_labels, junk_pts, np.asarray(assoc.valid))
        assert_same(jit_metrics(rig, assoc, scene), jit_metrics(rig, assoc2, scene2))


def test_jit_and_vmap_equal_eager():
    rig = make_rig()
    cases, batched = random_batch(4, 8)
    assert batched.g_f1.shape == (len(cases),)
    for b in (0, 1):
        scene, assoc = cases[b]
        eager = scene_metrics(rig, assoc, scene)
        assert_same(eager, jit_metrics(rig, assoc, scene))
        assert_same(eager, unstack(batched, b))


def test_mean_metrics_skips_scenes_without_groups(three_points):
    scene, instance, mask = three_points
    rig = make_rig()
    shift = np.pad(GT4 + np.array([0.0, 0.0, 0.1]), ((0, 3), (0, 0)))
    perfect = make_assoc(np.where(mask, instance, -1), shift)
    empty = make_assoc(-np.ones((4, 3), np.int32))
    per = [jit_metrics(rig, a, scene) for a in (perfect, empty, empty)]
    mean = mean_metrics(stack(per))
    assert mean["num_scenes"] == 3
    assert mean["g_f1"] == pytest.approx(1 / 3)
    assert mean["has_groups"] == pytest.approx(1 / 3)
    assert mean["err3d"] == pytest.approx(0.1, rel=1e-5)
    assert mean["bpe_px"] == pytest.approx(float(per[0].bpe_px))
    assert np.isnan(mean_metrics(stack(per[1:]))["err3d"])
    assert set(mean) == {f.name for f in dataclasses.fields(Metrics)} | {"num_scenes"}
