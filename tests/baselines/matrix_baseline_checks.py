"""Checks shared by the tests of the matrix baselines (MatchEIG, matchSVT, spectral
clustering): every method has the signature ``fn(rig, xy, mask, d, tau, sigma, thresholds,
options) -> (groups, valid, status)``.

Shapes are fixed (hand-made scene: 3 views × 5 slots; random scenes: 4 views × 12 slots)
so that each method compiles few programs.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
from helpers import project_np, ring_rig

from cdog_jax.geometry._epipolar import epipolar_distances
from cdog_jax.synthetic import default_rig, generate_scene

RANDOM_VIEWS, RANDOM_SLOTS, RANDOM_POINTS = 4, 12, 8


def tau_of(sigma):
    return jnp.maximum(2.0 * jnp.sqrt(jnp.float32(2.0)) * sigma, 1.0)


def thresholds_of(options):
    return {name: jnp.asarray(getattr(options, name), jnp.float32) for name in options.THRESHOLDS}


@functools.cache
def jitted(fn, options):
    """``run(rig, xy, mask, sigma, d=None) -> (groups, valid, status, d)``: the method jitted
    (one program per shape), ``d`` computed when not given."""

    @jax.jit
    def run(rig, xy, mask, d, sigma, thresholds):
        return fn(rig, xy, mask, d, tau_of(sigma), sigma, thresholds, options)

    def call(rig, xy, mask, sigma, d=None):
        d = _distances(rig, xy, mask) if d is None else d
        return *run(rig, xy, mask, d, jnp.float32(sigma), thresholds_of(options)), d

    return call


_distances = jax.jit(epipolar_distances)


def group_sets(groups, valid):
    """The valid groups as a set of frozensets of (view, slot); checks the table's invariants."""
    groups, valid = np.asarray(groups), np.asarray(valid)
    out = set()
    seen = set()
    for g in np.flatnonzero(valid):
        members = frozenset((m, int(s)) for m, s in enumerate(groups[g]) if s >= 0)
        assert len(members) >= 2, "a valid group has fewer than 2 members"
        assert not members & seen, "groups overlap"
        seen |= members
        out.add(members)
    return out


def truth_sets(instance):
    """Ground-truth groups (points with ≥ 2 detections) as frozensets of (view, slot)."""
    instance = np.asarray(instance)
    out = set()
    for p in np.unique(instance[instance >= 0]):
        members = frozenset((int(m), int(s)) for m, s in zip(*np.nonzero(instance == p)))
        if len(members) >= 2:
            out.add(members)
    return out


def pairs(sets):
    return {tuple(sorted(pair)) for s in sets for pair in _pairs_of(sorted(s))}


def _pairs_of(items):
    return [(a, b) for i, a in enumerate(items) for b in items[i + 1 :]]


def random_scene(seed, sigma=0.0):
    rig = default_rig().select(range(RANDOM_VIEWS))
    scene = generate_scene(
        jax.random.PRNGKey(seed), rig, RANDOM_POINTS, sigma, capacity=RANDOM_SLOTS
    )
    return rig, scene


def has_false_edge(d, instance, tau=1.0):
    """True when detections of two different points pass the gate ``max(d, dᵀ) < τ``."""
    d = np.asarray(d)
    cost = np.maximum(d, np.transpose(d, (2, 3, 0, 1)))
    inst = np.asarray(instance)
    different = inst[:, :, None, None] != inst[None, None, :, :]
    return bool(np.any(different & (cost < tau)))


def hand_scene():
    """4 views, 4 points (point 3 unseen in view 0, point 2 unseen in view 2), exact pixels
    in slots chosen by hand among 12, plus a second detection of point 0 in view 1, 0.3 px
    from the first (slot 8), which view-uniqueness must leave out of the group.

    Returns ``rig, xy, mask, instance, answers``: the two right answers (either copy of the
    duplicate joins point 0's group) as sets of groups."""
    rig = ring_rig(RANDOM_VIEWS, seed=3)
    X = np.array(
        [[0.32, -0.35, 0.14], [-0.02, 0.14, -0.37], [-0.36, -0.26, 0.38], [-0.16, 0.07, 0.39]]
    )
    xy_true, vis = project_np(rig, X)
    assert vis.all()
    # slot_of[m, p]: slot of point p in view m, -1 where view m does not see it.
    slot_of = np.array([[0, 5, 11, -1], [3, 0, 4, 1], [2, 9, -1, 0], [7, 6, 1, 10]])
    xy = np.zeros((RANDOM_VIEWS, RANDOM_SLOTS, 2), np.float32)
    instance = np.full((RANDOM_VIEWS, RANDOM_SLOTS), -1)
    for m, p in zip(*np.nonzero(slot_of >= 0)):
        xy[m, slot_of[m, p]] = xy_true[m, p]
        instance[m, slot_of[m, p]] = p
    xy[1, 8] = xy_true[1, 0] + np.array([0.3, 0.0])
    instance[1, 8] = 0
    groups = [
        frozenset((int(m), int(slot_of[m, p])) for m in range(RANDOM_VIEWS) if slot_of[m, p] >= 0)
        for p in range(4)
    ]
    swapped = [g - {(1, 3)} | {(1, 8)} if (1, 3) in g else g for g in groups]
    return rig, jnp.asarray(xy), jnp.asarray(instance >= 0), instance, (set(groups), set(swapped))


def check_hand_scene(fn, options):
    rig, xy, mask, instance, answers = hand_scene()
    groups, valid, status, d = jitted(fn, options)(rig, xy, mask, 0.0)
    # Unambiguous by construction but for the duplicate: different points are ≥ 20 px off
    # each other's epipolar lines.
    assert not has_false_edge(d, instance, tau=20.0)
    assert int(status) == 0
    assert group_sets(groups, valid) in answers


def check_noise_free(fn, options, seeds=range(16), min_clean=8):
    """Bound: every point detected in ≥ 2 views is grouped exactly (and nothing else is
    grouped) when no two different points pass the 1 px gate (no false edge). At least
    ``min_clean`` of the seeds must be such scenes, so that the check cannot pass empty."""
    run = jitted(fn, options)
    clean = 0
    for seed in seeds:
        rig, scene = random_scene(seed)
        groups, valid, status, d = run(rig, scene.xy, scene.mask, 0.0)
        if has_false_edge(d, scene.instance):
            continue
        clean += 1
        assert int(status) == 0
        assert group_sets(groups, valid) == truth_sets(scene.instance), f"seed {seed}"
    assert clean >= min_clean


def check_jit_vmap_padding_permutation(fn, options, sigma=1.0, seeds=(1, 2)):
    """jit equals eager; vmap over 2 scenes equals a loop; garbage in padded slots (pixels and
    distances) changes nothing; permuting the slots of every view permutes the groups."""
    rig, scene = random_scene(seeds[0], sigma)
    thresholds = thresholds_of(options)
    sig = jnp.float32(sigma)
    d = epipolar_distances(rig, scene.xy, scene.mask)
    eager = fn(rig, scene.xy, scene.mask, d, tau_of(sig), sig, thresholds, options)
    jit_out = jitted(fn, options)(rig, scene.xy, scene.mask, sigma)[:3]
    for a, b in zip(eager, jit_out):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))

    scenes = [random_scene(s, sigma)[1] for s in seeds]
    xy = jnp.stack([s.xy for s in scenes])
    mask = jnp.stack([s.mask for s in scenes])
    batched = _vmapped(fn, options)(rig, xy, mask, sig, thresholds)
    for b, s in enumerate(scenes):
        single = jitted(fn, options)(rig, s.xy, s.mask, sigma)[:3]
        for a, c in zip(single, batched):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(c)[b])

    # Garbage in padded slots: NaN / huge pixels, and NaN or 0 distances at padded entries.
    pad = ~scene.mask
    assert bool(pad.any())
    junk = jnp.where(pad[..., None], jnp.array([jnp.nan, 1e30], jnp.float32), scene.xy)
    d_junk = epipolar_distances(rig, junk, scene.mask)
    pad_pair = pad[:, :, None, None] | pad[None, None, :, :]
    # NaN, and 0 (inside every gate) where a padded slot meets a valid one.
    d_junk = jnp.where(
        pad_pair, jnp.where(pad[:, :, None, None] & pad[None, None, :, :], jnp.nan, 0.0), d_junk
    )
    dirty = jitted(fn, options)(rig, junk, scene.mask, sigma, d_junk)[:3]
    clean = jitted(fn, options)(rig, scene.xy, scene.mask, sigma)[:3]
    for a, b in zip(clean, dirty):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))

    # Slot permutation within each view.
    rng = np.random.default_rng(7)
    perm = np.stack(
        [rng.permutation(RANDOM_SLOTS) for _ in range(RANDOM_VIEWS)]
    )  # new slot s holds old perm[m, s]
    take = lambda a: jnp.asarray(
        np.take_along_axis(
            np.asarray(a), perm.reshape(perm.shape + (1,) * (np.ndim(a) - 2)), axis=1
        )
    )
    groups, valid, _, _ = jitted(fn, options)(rig, take(scene.xy), take(scene.mask), sigma)
    back = {frozenset((m, int(perm[m, s])) for m, s in g) for g in group_sets(groups, valid)}
    assert back == group_sets(clean[0], clean[1])


@functools.cache
def _vmapped(fn, options):
    def one(rig, xy, mask, sigma, thresholds):
        d = epipolar_distances(rig, xy, mask)
        return fn(rig, xy, mask, d, tau_of(sigma), sigma, thresholds, options)

    return jax.jit(jax.vmap(one, in_axes=(None, 0, 0, None, None)))
