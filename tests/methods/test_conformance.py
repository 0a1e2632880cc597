"""Every registered method obeys the method contract (docs/ARCHITECTURE.md): jit equals
eager (for the jittable ones), a batch equals a loop, padded slots change nothing, permuting slots permutes the
groups, and noise-free scenes without ambiguity are associated exactly.

The noise-free bound: when every pair of detections of *different* points is at least 3τ
from each other's epipolar lines (both directions; τ = 1 px at σ = 0), no wrong pair passes
any method's gate, so every point seen in ≥ 2 views must come back as exactly one group of
all its detections, and nothing else. Of the 12 scenes drawn (4 points each), at least 5 must
meet the condition, so that the check cannot pass vacuously.
"""

from __future__ import annotations

import jax
import numpy as np
import pytest

import cdog_jax
import mutual_nn_method  # noqa: F401  (registers "mutual_nn": a method from one module)
from cdog_jax import associate, associate_batch, method_from, method_names
from cdog_jax.geometry import epipolar_distances
from helpers import random_scene, ring_rig

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
    groups = {}
    for m, i in zip(*np.nonzero((np.asarray(labels) >= 0) & mask)):
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
    clear = [s for s in SCENES if _unambiguous(*s)]
    assert len(clear) >= 5, "too few unambiguous scenes to test"
    batch = associate_batch(RIG, np.stack([s[0] for s in clear]), np.stack([s[1] for s in clear]), method=name, sigma=SIGMA)
    for b, (xy, mask, inst) in enumerate(clear):
        assert _partition(batch.labels[b], mask) == _truth(inst, mask), f"{name}: scene {b}"


@pytest.mark.parametrize("name", METHODS)
def test_batch_equals_a_loop_and_padding_changes_nothing(name):
    xy = np.stack([s[0] for s in SCENES[:3]])
    mask = np.stack([s[1] for s in SCENES[:3]])
    xy[:, 1, 0] = 1.0  # noise so that methods do real work
    batch = associate_batch(RIG, xy, mask, method=name, sigma=1.0)
    garbage = np.where(mask[..., None], xy, np.float32(np.nan))  # padding: NaN, and 1e30 in view 0
    garbage[:, 0] = np.where(mask[:, 0, :, None], xy[:, 0], np.float32(1e30))
    for b in range(3):
        one = associate(RIG, xy[b], mask[b], method=name, sigma=1.0)
        np.testing.assert_array_equal(one.labels, batch.labels[b])
        np.testing.assert_allclose(one.points3d, batch.points3d[b], rtol=1e-5, atol=1e-5)
        dirty = associate(RIG, garbage[b], mask[b], method=name, sigma=1.0)
        np.testing.assert_array_equal(dirty.labels, one.labels)
        np.testing.assert_array_equal(dirty.points3d, one.points3d)


@pytest.mark.parametrize("name", METHODS)
def test_slot_permutation_permutes_the_groups(name):
    xy, mask, _ = SCENES[1]
    xy = xy + np.float32(0.3) * np.random.default_rng(0).standard_normal(xy.shape).astype(np.float32)
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
    method = method_from(name, "test")
    xy, mask, _ = SCENES[2]
    th = method.thresholds(1.0)
    obs = cdog_jax.Observations(jax.numpy.asarray(xy), jax.numpy.asarray(mask))
    jitted = jax.jit(lambda o, t: method.associate_scene(RIG, o, t))(obs, th)
    eager = method.associate_scene(RIG, obs, th)
    np.testing.assert_array_equal(jitted.labels, eager.labels)
    np.testing.assert_allclose(jitted.points3d, eager.points3d, rtol=1e-4, atol=1e-4)
