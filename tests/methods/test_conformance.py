"""Every registered method obeys the method contract (docs/ARCHITECTURE.md): jit equals
eager (for the jittable ones), a batch equals a loop, padded slots change nothing, permuting slots permutes the
groups, and noise-free scenes without ambiguity are associated exactly.

The noise-free bound: when every pair of detections of *different* points is at least 3τ
from each other's epipolar lines (both directions; τ = 1 px at σ = 0), no wrong pair passes
any method's gate, so every point seen in ≥ 2 views must come back as exactly one group of
all its detections, and nothing else. The first 4 of the 12 scenes drawn (4 points each)
that meet the condition are checked; there must be 4, so that the check cannot pass vacuously.

Every test runs each method at the same shapes (4 views, 8 slots padded to 32, batches of
4), so each method compiles one single-scene and one batched program for the whole file.
"""

from __future__ import annotations

import jax
import mutual_nn_method  # noqa: F401  (registers "mutual_nn": a method from one module)
import numpy as np
import pytest
from helpers import random_scene, ring_rig

import cdog_jax
from cdog_jax import associate, associate_batch, method_from, method_names
from cdog_jax.geometry import epipolar_distances

RIG = ring_rig(4)
P = 8
METHODS = method_names()
SIGMA = 0.0


def _scenes(count=12, points=4):
    out = []
    for seed in range(count):
        xy, mask, inst, _ = random_scene(RIG, points, P, sigma=SIGMA, seed=100 + seed)
        out.append((xy.astype(np.float32), mask, inst))
    return out


SCENES = _scenes()


def _partition(labels, mask):
    """The groups as a set of frozensets of (view, slot)."""
    groups, labels = {}, np.asarray(labels)  # read on the host once, not slot by slot
    for m, i in zip(*np.nonzero((labels >= 0) & mask)):
        groups.setdefault(int(labels[m, i]), set()).add((int(m), int(i)))
    return {frozenset(g) for g in groups.values()}


def _truth(inst, mask):
    groups = {}
    for m, i in zip(*np.nonzero((inst >= 0) & mask)):
        groups.setdefault(int(inst[m, i]), set()).add((int(m), int(i)))
    return {frozenset(g) for g in groups.values() if len(g) >= 2}


def _unambiguous(xy, mask, inst, tau=1.0):
    d = np.asarray(epipolar_distances(RIG, jax.numpy.asarray(xy), jax.numpy.asarray(mask)))
    wrong = (inst[:, :, None, None] != inst[None, None, :, :]) | (inst[:, :, None, None] < 0)
    both = np.minimum(d, d.transpose(2, 3, 0, 1))
    return bool(np.all(np.where(wrong & np.isfinite(both), both, np.inf) >= 3 * tau))


@pytest.mark.parametrize("name", METHODS)
def test_noise_free_scenes_associate_exactly(name):
    clear = [s for s in SCENES if _unambiguous(*s)][:4]
    assert len(clear) == 4, "too few unambiguous scenes to test"
    batch = associate_batch(
        RIG,
        np.stack([s[0] for s in clear]),
        np.stack([s[1] for s in clear]),
        method=name,
        sigma=SIGMA,
    )
    for b, (_xy, mask, inst) in enumerate(clear):
        assert _partition(batch.labels[b], mask) == _truth(inst, mask), f"{name}: scene {b}"


@pytest.mark.parametrize("name", METHODS)
def test_batch_equals_a_loop_and_padding_changes_nothing(name):
    xy = np.stack([s[0] for s in SCENES[:4]])
    mask = np.stack([s[1] for s in SCENES[:4]])
    xy[:, 1, 0] = 1.0  # noise so that methods do real work
    batch = associate_batch(RIG, xy, mask, method=name, sigma=1.0)
    garbage = np.where(mask[..., None], xy, np.float32(np.nan))  # padding: NaN, and 1e30 in view 0
    garbage[:, 0] = np.where(mask[:, 0, :, None], xy[:, 0], np.float32(1e30))
    for b in range(4):
        one = associate(RIG, xy[b], mask[b], method=name, sigma=1.0)
        np.testing.assert_array_equal(one.labels, batch.labels[b])
        np.testing.assert_allclose(one.points3d, batch.points3d[b], rtol=1e-5, atol=1e-5)
        dirty = associate(RIG, garbage[b], mask[b], method=name, sigma=1.0)
        np.testing.assert_array_equal(dirty.labels, one.labels)
        np.testing.assert_array_equal(dirty.points3d, one.points3d)


@pytest.mark.parametrize("name", METHODS)
def test_slot_permutation_permutes_the_groups(name):
    xy, mask, _ = SCENES[1]
    xy = xy + np.float32(0.3) * np.random.default_rng(0).standard_normal(xy.shape).astype(
        np.float32
    )
    perm = np.stack([np.random.default_rng(m).permutation(P) for m in range(RIG.num_views)])
    xy_p = np.take_along_axis(xy, perm[..., None], axis=1)
    mask_p = np.take_along_axis(mask, perm, axis=1)
    a = associate(RIG, xy, mask, method=name, sigma=1.0)
    b = associate(RIG, xy_p, mask_p, method=name, sigma=1.0)
    back = {frozenset((m, int(perm[m, i])) for m, i in g) for g in _partition(b.labels, mask_p)}
    assert back == _partition(a.labels, mask)


JITTABLE = tuple(name for name in METHODS if method_from(name, "test").jittable)


@pytest.mark.parametrize("name", JITTABLE)  # a host method (jittable False) is never jitted
def test_jit_equals_eager(name):
    """``associate`` (the jitted per-scene function at 32 slots, compiled above) against the
    method's function called eagerly on the same padded scene."""
    method = method_from(name, "test")
    xy, mask, _ = SCENES[2]
    jitted = associate(RIG, xy, mask, method=name, sigma=1.0)
    pad = ((0, 0), (0, 32 - P))
    obs = cdog_jax.Observations(
        jax.numpy.asarray(np.pad(xy, (*pad, (0, 0)))), jax.numpy.asarray(np.pad(mask, pad))
    )
    eager = method.associate_scene(RIG, obs, method.thresholds(1.0))
    np.testing.assert_array_equal(jitted.labels, np.asarray(eager.labels)[:, :P])
    np.testing.assert_allclose(
        jitted.points3d,
        np.asarray(eager.points3d)[: jitted.points3d.shape[0]],
        rtol=1e-4,
        atol=1e-4,
    )
