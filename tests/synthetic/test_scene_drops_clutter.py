"""Missed detections and clutter in the benchmark scenes (docs/BENCHMARK.md §1, beyond the paper)."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cdog_jax._result import Association
from cdog_jax.metrics import scene_metrics
from cdog_jax.synthetic import IMAGE_SIZE, default_rig, generate_scene, generate_scenes

RIG = default_rig()
M = RIG.num_views
# One capacity, one clutter capacity and one batch size: every new shape costs a compile.
P, C, B = 40, 24, 16
TRACES = []


@functools.partial(jax.jit, static_argnames=("clutter_capacity",))
def _batch_jit(key, num_points, sigma_px, drop_rate, clutter_rate, *, clutter_capacity):
    TRACES.append(None)
    return generate_scenes(
        key,
        RIG,
        num_points,
        sigma_px,
        capacity=P,
        drop_rate=drop_rate,
        clutter_rate=clutter_rate,
        clutter_capacity=clutter_capacity,
    )


def batch(key, drop_rate=0.0, clutter_rate=0.0, clutter_capacity=C, num_points=P, sigma_px=1.0):
    """B scenes of ``num_points`` points; rates traced, per scene ``(B,)`` float32 (so
    scalar and per-scene rates share one cache entry)."""
    return _batch_jit(
        key,
        jnp.full((B,), num_points, jnp.int32),
        jnp.full((B,), sigma_px, jnp.float32),
        jnp.broadcast_to(jnp.asarray(drop_rate, jnp.float32), (B,)),
        jnp.broadcast_to(jnp.asarray(clutter_rate, jnp.float32), (B,)),
        clutter_capacity=clutter_capacity,
    )


def one(scenes, b=0):
    return jax.tree.map(lambda a: a[b], scenes)


def detections(scene):
    """``{(view, instance): xy}`` of the real (instance ≥ 0) valid detections of one scene."""
    mask, inst, xy = (np.asarray(a) for a in (scene.mask, scene.instance, scene.xy))
    return {
        (m, int(inst[m, i])): tuple(xy[m, i])
        for m in range(M)
        for i in range(mask.shape[1])
        if inst[m, i] >= 0
    }


def test_defaults_are_the_paper_scene():
    key = jax.random.PRNGKey(11)
    args = (key, RIG, jnp.full((B,), P, jnp.int32), jnp.full((B,), 1.0, jnp.float32))
    plain = generate_scenes(*args, capacity=P)
    zero = generate_scenes(*args, capacity=P, drop_rate=0.0, clutter_rate=0.0, clutter_capacity=0)
    for a, b in zip(jax.tree.leaves(plain), jax.tree.leaves(zero)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    np.testing.assert_array_equal(np.asarray(plain.num_clutter), 0)
    # Clutter slots (even filled ones) and drops leave the points and their noisy pixels
    # untouched: only the new fold_in streams differ (pixels to rounding: the outer jit of
    # `batch` fuses differently).
    cl = batch(key, drop_rate=0.3, clutter_rate=5.0)
    assert cl.xy.shape == (B, M, P + C, 2) and cl.points3d.shape == (B, P + C, 3)
    np.testing.assert_array_equal(np.asarray(cl.points3d)[:, :P], np.asarray(plain.points3d))
    np.testing.assert_array_equal(np.asarray(cl.num_points), np.asarray(plain.num_points))
    for b in range(3):
        full, kept = detections(one(plain, b)), detections(one(cl, b))
        assert set(kept) <= set(full) and len(kept) < len(full)
        np.testing.assert_allclose([kept[k] for k in kept], [full[k] for k in kept], atol=1e-3)


def test_drop_rate_drops_that_share():
    # Same keys with and without drops: the visible detections are the same (chosen before
    # the drops), and each survives independently with probability 0.7. With n ≈ 16 · 40 ·
    # 4.8 ≈ 3,000 detections the dropped share has std √(0.3 · 0.7 / n) ≈ 0.008; 0.04 is
    # five standard deviations (a false alarm about once in 10⁶ runs, and the keys are fixed).
    key = jax.random.PRNGKey(5)
    full, dropped = batch(key), batch(key, drop_rate=0.3)
    n = int(np.sum(np.asarray(full.instance) >= 0))
    kept = int(np.sum(np.asarray(dropped.instance) >= 0))
    assert n > 2500
    assert abs((n - kept) / n - 0.3) < 0.04
    # A point may be left with fewer than 2 detections: it is still an instance of the scene.
    per_point = np.stack(
        [np.bincount(np.asarray(s)[np.asarray(s) >= 0], minlength=P) for s in dropped.instance]
    )
    assert np.all(
        per_point
        <= np.stack(
            [np.bincount(np.asarray(s)[np.asarray(s) >= 0], minlength=P) for s in full.instance]
        )
    )
    assert np.any(per_point == 1)
    # Rate 1 drops everything, clutter only remains.
    none = batch(key, drop_rate=1.0, clutter_rate=2.0, clutter_capacity=C)
    assert not np.any(np.asarray(none.instance) >= 0)
    np.testing.assert_array_equal(np.asarray(none.mask).sum(-1), np.asarray(none.num_clutter))


def test_clutter_count_ids_and_positions():
    s = batch(jax.random.PRNGKey(6), clutter_rate=5.0)
    mask, inst, xy = np.asarray(s.mask), np.asarray(s.instance), np.asarray(s.xy)
    clutter = mask & (inst == -1)
    count = np.asarray(s.num_clutter)  # (B, M)
    np.testing.assert_array_equal(clutter.sum(-1), count)
    # B · M = 160 Poisson(5) draws (P(count > C = 24) < 1e-9: no clipping): the mean has
    # std √(5 / 160) ≈ 0.18, so ±0.9 is five standard deviations.
    assert abs(count.mean() - 5.0) < 0.9
    w, h = IMAGE_SIZE
    cxy = xy[clutter]
    assert np.all((cxy[:, 0] >= 0) & (cxy[:, 0] < w) & (cxy[:, 1] >= 0) & (cxy[:, 1] < h))
    assert cxy[:, 0].std() > w / 5 and cxy[:, 1].std() > h / 5  # spread over the image
    # Real detections are untouched by the clutter: each instance at most once per view.
    for b in range(B):
        for m in range(M):
            ids = inst[b, m][inst[b, m] >= 0]
            assert len(np.unique(ids)) == len(ids)
    # Clipping: at most clutter_capacity per view, visible in num_clutter. At rate 20,
    # P(Poisson ≥ 24) ≈ 0.16 (≈ 25 of 160 views, std 5) and E min(Poisson, 24) ≈ 19.5.
    clipped = batch(jax.random.PRNGKey(6), clutter_rate=20.0)
    cnt = np.asarray(clipped.num_clutter)
    assert cnt.max() == C and 5 <= np.sum(cnt == C) <= 50 and abs(cnt.mean() - 19.5) < 1.5
    np.testing.assert_array_equal(
        (np.asarray(clipped.mask) & (np.asarray(clipped.instance) == -1)).sum(-1), cnt
    )


def test_shuffle_mixes_clutter_with_real_detections():
    # Uniform slot permutations: a clutter detection is in the first P of the P + C slots
    # with probability P / (P + C) = 0.625. About 800 clutter detections → std ≈ 0.017.
    s = batch(jax.random.PRNGKey(7), clutter_rate=5.0)
    clutter = np.asarray(s.mask) & (np.asarray(s.instance) == -1)
    slot = np.nonzero(clutter)[-1]
    assert abs(np.mean(slot < P) - P / (P + C)) < 0.09
    # And real detections reach the clutter rows' slots too.
    real = np.nonzero(np.asarray(s.instance) >= 0)[-1]
    assert np.mean(real >= P) > 0.2


def _truth_association(scene):
    """The perfect answer: one group per instance with ≥ 2 detections, the rest unassigned."""
    inst, mask = np.asarray(scene.instance), np.asarray(scene.mask)
    Mv, Ps = inst.shape
    G = Mv * Ps // 2
    counts = np.bincount(inst[mask & (inst >= 0)], minlength=Ps)
    ids = np.nonzero(counts >= 2)[0]
    gid = -np.ones(Ps, np.int32)
    gid[ids] = np.arange(len(ids))
    labels = np.where(inst >= 0, gid[np.maximum(inst, 0)], -1).astype(np.int32)
    groups = -np.ones((G, Mv), np.int32)
    for m, i in zip(*np.nonzero(labels >= 0)):
        groups[labels[m, i], m] = i
    valid = np.arange(G) < len(ids)
    pts = np.zeros((G, 3), np.float32)
    pts[: len(ids)] = np.asarray(scene.points3d)[ids]
    return Association(
        labels=jnp.asarray(labels),
        groups=jnp.asarray(groups),
        valid=jnp.asarray(valid),
        points3d=jnp.asarray(pts),
        bpe=jnp.zeros((G,)),
        err_px=jnp.zeros((G,)),
        n_views=jnp.asarray((groups >= 0).sum(1).astype(np.int32)),
        num_groups=jnp.asarray(len(ids), jnp.int32),
        sigma_px=jnp.asarray(0.0),
        tau_px=jnp.asarray(0.0),
        status=jnp.int32(0),
    ), len(ids)


def test_perfect_association_of_a_dropped_cluttered_scene_scores_one():
    scene = one(batch(jax.random.PRNGKey(8), drop_rate=0.3, clutter_rate=5.0, sigma_px=0.0))
    inst, mask = np.asarray(scene.instance), np.asarray(scene.mask)
    counts = np.bincount(inst[mask & (inst >= 0)], minlength=P + C)
    assert np.any(counts == 1) and np.sum(mask & (inst == -1)) > 0  # the case is non-trivial
    assoc, num_gt = _truth_association(scene)
    m = jax.jit(scene_metrics)(RIG, assoc, scene)
    for f in ("pg_p", "pg_r", "pg_f1", "mp_p", "mp_r", "mp_f1", "g_r"):
        assert float(getattr(m, f)) == pytest.approx(1.0), f
    assert int(m.num_gt_groups) == num_gt
    assert float(m.err3d) == pytest.approx(0.0, abs=1e-5)
    # G- counts every unassigned detection (clutter, and the lone detection of a point seen
    # once after the drops) as a singleton prediction, so even the truth has G-P < 1.
    singles = int(np.sum(mask)) - int(np.sum(counts[counts >= 2]))
    assert int(m.num_unassigned) == singles
    assert float(m.g_p) == pytest.approx(num_gt / (num_gt + singles))


def test_traced_rates_compile_once_and_vmap():
    key = jax.random.PRNGKey(9)
    before = len(TRACES)
    batch(key)  # maybe compiled by an earlier test
    traced = len(TRACES)
    means = []
    for drop, clutter in ((0.1, 1.0), (0.2, 3.0), (0.5, 8.0)):
        s = batch(key, drop_rate=drop, clutter_rate=clutter)
        means.append(float(np.asarray(s.num_clutter).mean()))
    assert means[0] < means[1] < means[2]
    # Per-scene rates, vmapped: scene b gets drop_rate[b] and clutter_rate[b].
    drop = jnp.linspace(0.0, 0.9, B).astype(jnp.float32)
    clut = jnp.linspace(0.0, 12.0, B).astype(jnp.float32)
    s = batch(key, drop_rate=drop, clutter_rate=clut)
    assert len(TRACES) == traced <= before + 1  # no new trace for new rates
    real = (np.asarray(s.instance) >= 0).sum((1, 2))
    assert real[0] > real[-1] and int(np.asarray(s.num_clutter)[0].sum()) == 0
    assert np.asarray(s.num_clutter)[-1].mean() > 6.0


def test_bad_arguments():
    with pytest.raises(ValueError, match="drop_rate"):
        generate_scene(jax.random.PRNGKey(0), RIG, 3, 1.0, capacity=P, drop_rate=1.5)
    with pytest.raises(ValueError, match="clutter_rate"):
        generate_scene(jax.random.PRNGKey(0), RIG, 3, 1.0, capacity=P, clutter_rate=-1.0)
    with pytest.raises(ValueError, match="clutter_capacity"):
        generate_scene(jax.random.PRNGKey(0), RIG, 3, 1.0, capacity=P, clutter_capacity=-1)
    with pytest.raises(ValueError, match=r"shape \(B,\)"):
        generate_scenes(
            jax.random.PRNGKey(0),
            RIG,
            jnp.ones((B,), jnp.int32),
            jnp.ones((B,)),
            capacity=P,
            drop_rate=jnp.ones((3,)),
        )
