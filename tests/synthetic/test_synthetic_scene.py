"""Benchmark scene generation (docs/BENCHMARK.md §1): visibility, noise, shuffled slots, jit and vmap."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cdog_jax.geometry._projection import project
from cdog_jax.synthetic import IMAGE_SIZE, default_rig, generate_scene, generate_scenes
from cdog_jax.synthetic._rig import negate_intrinsics

RIG = default_rig()
M = RIG.num_views
# One capacity and one batch size for every test: each new shape costs a compilation.
P, B = 8, 16
TRACES = []  # traces of the jitted batch generator

gen = generate_scene  # jitted inside: eager calls compile once per shape


@functools.partial(jax.jit, static_argnames=("capacity",))
def _gen_many_jit(key, rig, num_points, sigma_px, *, capacity):
    TRACES.append(None)
    return generate_scenes(key, rig, num_points, sigma_px, capacity=capacity)


def gen_many(key, rig, num_points, sigma_px, *, capacity):
    """The batch generator under an outer jit, counting its traces (canonical dtypes: a
    weak-typed argument would be a new cache entry)."""
    num_points = jnp.asarray(num_points, dtype=jnp.int32)
    sigma_px = jnp.asarray(sigma_px, dtype=rig.K.dtype)
    return _gen_many_jit(key, rig, num_points, sigma_px, capacity=capacity)


project_points = jax.jit(jax.vmap(project, in_axes=(None, 0)))  # (S, 3) → (S, M, 2), (S, M)


def _exact_xy(rig, scene):
    """Noise-free pixels ``(M, P, 2)`` of each slot's instance, and in-image flags."""
    xy, front = project_points(rig, scene.points3d)  # (P, M, 2), (P, M)
    inst = np.maximum(np.asarray(scene.instance), 0)
    view = np.arange(M)[:, None]
    xy, front = np.asarray(xy), np.asarray(front)
    w, h = IMAGE_SIZE
    inside = front & (xy[..., 0] >= 0) & (xy[..., 0] < w) & (xy[..., 1] >= 0) & (xy[..., 1] < h)
    return xy[inst, view], inside  # (M, P, 2), (P, M) by instance id


def _check_invariants(rig, scene, capacity):
    xy, mask, inst = np.asarray(scene.xy), np.asarray(scene.mask), np.asarray(scene.instance)
    n = int(scene.num_points)
    assert xy.shape == (M, capacity, 2) and mask.shape == inst.shape == (M, capacity)
    assert scene.points3d.shape == (capacity, 3) and inst.dtype == np.int32
    assert 0 <= n <= capacity
    # Padding is neutral and labelled -1; valid slots hold ids 0..n-1, at most once per view.
    np.testing.assert_array_equal(inst == -1, ~mask)
    np.testing.assert_array_equal(xy[~mask], 0.0)
    assert np.all(inst[mask] < n)
    np.testing.assert_array_equal(np.asarray(scene.points3d)[n:], 0.0)
    # Masks agree with the visibility of the ground-truth points; each instance in >= 2 views.
    _, inside = _exact_xy(rig, scene)
    seen = np.zeros((n, M), bool)
    for m in range(M):
        ids = inst[m][mask[m]]
        assert len(np.unique(ids)) == len(ids)
        seen[ids, m] = True
    np.testing.assert_array_equal(seen, inside[:n])
    np.testing.assert_array_equal(mask.sum(-1), inside[:n].sum(0))
    assert np.all(seen.sum(-1) >= 2)


@pytest.mark.parametrize("num_points", [0, 1, 5, P])
def test_invariants(getkey, num_points):
    scene = gen(getkey(), RIG, num_points, 1.0, capacity=P)
    assert int(scene.num_points) == num_points
    _check_invariants(RIG, scene, P)


def test_sigma_zero_is_exact(getkey):
    scene = gen(getkey(), RIG, P, 0.0, capacity=P)
    xy_exact, _ = _exact_xy(RIG, scene)
    mask = np.asarray(scene.mask)
    np.testing.assert_allclose(np.asarray(scene.xy)[mask], xy_exact[mask], atol=1e-3)


def test_noise_std(getkey):
    sigma = 2.0
    scenes = gen_many(getkey(), RIG, jnp.full((B,), P), jnp.full((B,), sigma), capacity=P)
    residuals = []
    for b in range(B):
        scene = jax.tree.map(lambda a: a[b], scenes)
        xy_exact, _ = _exact_xy(RIG, scene)
        mask = np.asarray(scene.mask)
        residuals.append(np.asarray(scene.xy)[mask] - xy_exact[mask])
    r = np.concatenate(residuals)  # (K, 2), about 600 detections
    assert len(r) > 400
    assert abs(r.mean()) < 0.1
    np.testing.assert_allclose(r.std(axis=0), sigma, rtol=0.1)


def test_noise_may_leave_the_image(getkey):
    # Visibility is decided before the noise: noisy detections outside the image are kept.
    scenes = gen_many(getkey(), RIG, jnp.full((B,), P), jnp.full((B,), 50.0), capacity=P)
    xy, mask = np.asarray(scenes.xy), np.asarray(scenes.mask)
    w, h = IMAGE_SIZE
    outside = (xy[..., 0] < 0) | (xy[..., 0] >= w) | (xy[..., 1] < 0) | (xy[..., 1] >= h)
    assert np.any(outside & mask)


def test_slots_are_shuffled(getkey):
    scene = gen(getkey(), RIG, 6, 0.5, capacity=P)
    mask, inst = np.asarray(scene.mask), np.asarray(scene.instance)
    # Padding is not packed at the end of every view.
    packed = [np.all(mask[m, : mask[m].sum()]) for m in range(M)]
    assert not all(packed)
    # Valid slots are not in instance order, and the order differs between views.
    ordered = [np.all(np.diff(inst[m][mask[m]]) > 0) for m in range(M) if mask[m].sum() >= 2]
    assert not all(ordered)
    slot_of = {}
    for m in range(M):
        for s in np.flatnonzero(mask[m]):
            slot_of.setdefault(int(inst[m, s]), set()).add(int(s))
    assert any(len(slots) > 1 for slots in slot_of.values())


def test_slot_positions_are_uniform(getkey):
    scenes = gen_many(getkey(), RIG, jnp.full((B,), 4), jnp.zeros((B,)), capacity=P)
    mask = np.asarray(scenes.mask)  # (B, M, P), about 16 * 4 * 4.8 detections
    slot = np.broadcast_to(np.arange(P), mask.shape)
    assert abs(slot[mask].mean() - (P - 1) / 2) < 0.5


def test_same_key_same_scene(getkey):
    key = getkey()
    a, b = gen(key, RIG, 6, 1.5, capacity=P), gen(key, RIG, 6, 1.5, capacity=P)
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
        np.testing.assert_array_equal(x, y)
    c = gen(getkey(), RIG, 6, 1.5, capacity=P)
    assert not np.array_equal(a.points3d, c.points3d)


def test_jit_vmap_matches_single_scenes(getkey):
    # Traced counts and noise levels: other values reuse the compiled batch generator.
    gen_many(getkey(), RIG, jnp.full((B,), 1), jnp.zeros((B,)), capacity=P)
    n_traces = len(TRACES)
    key = getkey()
    counts = jnp.array([0, 3, P, 5] * (B // 4), dtype=jnp.int32)
    sigmas = jnp.linspace(0.0, 5.0, B)
    batch = gen_many(key, RIG, counts, sigmas, capacity=P)
    assert len(TRACES) == n_traces
    assert batch.xy.shape == (B, M, P, 2) and batch.num_points.shape == (B,)
    np.testing.assert_array_equal(batch.num_points, counts)
    for b, k in list(enumerate(jax.random.split(key, B)))[:4]:
        single = gen(k, RIG, counts[b], sigmas[b], capacity=P)
        for x, y in zip(jax.tree.leaves(single), jax.tree.leaves(batch)):
            np.testing.assert_allclose(x, y[b], atol=1e-4)
        _check_invariants(RIG, single, P)


def test_too_few_candidates_and_empty_scene(getkey):
    # All candidates behind every camera: no instance at all.
    scene = gen(getkey(), RIG, 4, 1.0, capacity=P, box=((0.0, 0.0, 50.0), (1.0, 1.0, 51.0)))
    assert int(scene.num_points) == 0
    assert not np.asarray(scene.mask).any()
    np.testing.assert_array_equal(scene.instance, -1)
    np.testing.assert_array_equal(scene.xy, 0.0)
    # A huge box: few of the 4 P candidates are seen twice, so fewer instances than asked.
    scene = gen(
        getkey(), RIG, P, 1.0, capacity=P, box=np.array([[-20.0, -20.0, 0.0], [20.0, 20.0, 0.5]])
    )
    assert int(scene.num_points) < P
    _check_invariants(RIG, scene, P)


def test_negated_intrinsics_give_the_same_scene(getkey):
    key = getkey()
    neg = negate_intrinsics(RIG, [1, 4])
    a, b = gen(key, RIG, P, 1.0, capacity=P), gen(key, neg, P, 1.0, capacity=P)
    np.testing.assert_array_equal(a.mask, b.mask)
    np.testing.assert_array_equal(a.instance, b.instance)
    np.testing.assert_allclose(a.xy, b.xy, atol=1e-3)


def test_bad_arguments(getkey):
    with pytest.raises(ValueError, match="capacity"):
        generate_scene(getkey(), RIG, 1, 0.0, capacity=0)
    with pytest.raises(ValueError, match="num_points"):
        generate_scene(getkey(), RIG, 9, 0.0, capacity=8)
    with pytest.raises(ValueError, match="oversample"):
        generate_scene(getkey(), RIG, 1, 0.0, capacity=8, oversample=0)
    # The jaxtyping checker (TypeError) may catch mismatched batch shapes before we do.
    with pytest.raises((ValueError, TypeError)):
        generate_scenes(getkey(), RIG, jnp.array([1, 2]), jnp.array([0.0, 1.0, 2.0]), capacity=8)
