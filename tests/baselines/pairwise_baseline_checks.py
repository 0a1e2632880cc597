"""Checks shared by the baseline tests: one runner, the group-table invariants, scenes with
known answers, and comparisons of group tables as sets (slot order carries no meaning).

Every test runs scenes of one shape, ``M = 4`` views and ``P = 12`` slots, so that each
method compiles once per mode (jit, vmap)."""

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from cdog_jax.geometry import epipolar_distances, project
from cdog_jax.synthetic import default_rig, generate_scene

M, P = 4, 12


def gate(sigma: float) -> float:
    """The shared σ-matched epipolar gate τ (px)."""
    return max(2.0 * math.sqrt(2.0) * sigma, 1.0)


def run(fn, options, rig, xy, mask, sigma, d=None):
    """``fn``'s group table on one scene, as the method wrapper calls it."""
    dtype = xy.dtype
    sigma = jnp.asarray(sigma, dtype)
    tau = jnp.maximum(2.0 * jnp.sqrt(jnp.asarray(2.0, dtype)) * sigma, jnp.asarray(1.0, dtype))
    if d is None:
        d = epipolar_distances(rig, xy, mask)
    thresholds = {name: jnp.asarray(getattr(options, name), dtype) for name in options.THRESHOLDS}
    return fn(rig, xy, mask, d, tau, sigma, thresholds, options)


distances = jax.jit(epipolar_distances)


@functools.cache
def _compiled(fn, options):
    return jax.jit(lambda rig, xy, mask, d, sigma: run(fn, options, rig, xy, mask, sigma, d))


def jitted(fn, options):
    """``f(rig, xy, mask, sigma)``: the jitted method (the distances computed apart, so
    that a test may hand it a table with garbage in its padded entries)."""
    compiled = _compiled(fn, options)
    return lambda rig, xy, mask, sigma, d=None: compiled(
        rig, xy, mask, distances(rig, xy, mask) if d is None else d, sigma
    )


@functools.cache
def vmapped(fn, options):
    return jax.jit(
        jax.vmap(
            lambda rig, xy, mask, sigma: run(fn, options, rig, xy, mask, sigma),
            in_axes=(None, 0, 0, None),
        )
    )


def group_sets(groups, valid) -> set[frozenset]:
    """The valid groups as a set of frozensets of ``(view, slot)``."""
    groups, valid = np.asarray(groups), np.asarray(valid)
    return {frozenset((m, int(s)) for m, s in enumerate(row) if s >= 0) for row in groups[valid]}


def truth_sets(instance, mask) -> set[frozenset]:
    """Ground-truth groups (instances with ≥ 2 detections) as frozensets of ``(view, slot)``."""
    instance, mask = np.asarray(instance), np.asarray(mask)
    by_id: dict[int, set] = {}
    for m, s in zip(*np.nonzero(mask & (instance >= 0))):
        by_id.setdefault(int(instance[m, s]), set()).add((int(m), int(s)))
    return {frozenset(v) for v in by_id.values() if len(v) >= 2}


def check_table(groups, valid, status, mask) -> None:
    """The contract of every group table: shapes and dtypes, valid groups first and ordered
    by their smallest node ``m · P + i``, ≥ 2 members per valid group, at most one
    detection per view (by construction of the table), disjoint groups, only masked-in
    slots."""
    mask = np.asarray(mask)
    Mv, Pv = mask.shape
    assert groups.shape == (Mv * Pv // 2, Mv) and groups.dtype == jnp.int32
    assert valid.shape == (Mv * Pv // 2,) and valid.dtype == jnp.bool_
    assert status.shape == () and status.dtype == jnp.int32
    valid = np.asarray(valid)
    assert not np.any(valid[np.argmin(valid) :]) if not valid.all() else True, (
        "valid groups must come first"
    )
    g = np.asarray(groups)[valid]
    first_node = np.min(np.where(g >= 0, np.arange(Mv)[None, :] * Pv + g, Mv * Pv), axis=1)
    assert np.all(np.diff(first_node) > 0), "groups must be ordered by their smallest node"
    assert np.all((g >= -1) & (g < Pv))
    assert np.all(np.sum(g >= 0, axis=1) >= 2)
    members = [(m, s) for row in g for m, s in enumerate(row) if s >= 0]
    assert len(members) == len(set(members)), "a detection is in two groups"
    assert all(mask[m, s] for m, s in members), "a padded slot is in a group"


def random_scene(seed: int, sigma: float, num_points: int = 8):
    """A benchmark scene of the default rig's first four views, ``P = 12`` slots."""
    rig = default_rig(num_views=M)
    return rig, generate_scene(jax.random.PRNGKey(seed), rig, num_points, sigma, capacity=P)


def min_cross_cost(rig, xy, mask, instance) -> float:
    """The smallest symmetric epipolar cost (px) between detections of different points
    (clutter counts as its own point), the quantity the noise-free bounds are stated in."""
    d = np.asarray(distances(rig, xy, mask), np.float64)
    c = 0.5 * (d + d.transpose(2, 3, 0, 1))
    inst = np.asarray(instance)
    same = (inst[:, :, None, None] == inst[None, None]) & (inst[:, :, None, None] >= 0)
    return float(np.min(np.where(same, np.inf, c)))


# Four points of the default rig's box, all in front of the first three views; point 3 is
# left out of view 0 and view 3 is empty, so the answer is three 3-view groups and one
# 2-view group.
HAND_POINTS = np.array([[0.0, 0.0, 0.0], [0.2, 0.1, 0.15], [-0.2, 0.2, -0.1], [0.15, -0.25, 0.1]])
HAND_SLOTS = {0: [5, 0, 9, -1], 1: [3, 11, 0, 7], 2: [1, 4, 8, 2]}  # view → slot of point p


def hand_scene():
    """``rig, xy (4, 12, 2), mask, expected groups`` of the hand-made scene; padded slots
    hold NaN."""
    rig = default_rig(num_views=M)
    pix, front = project(rig, jnp.asarray(HAND_POINTS, rig.K.dtype))
    pix, front = np.asarray(pix), np.asarray(front)
    assert front.all()
    xy = np.full((M, P, 2), np.nan, np.float32)
    mask = np.zeros((M, P), bool)
    expected: dict[int, set] = {p: set() for p in range(len(HAND_POINTS))}
    for m, slots in HAND_SLOTS.items():
        for p, s in enumerate(slots):
            if s >= 0:
                xy[m, s], mask[m, s] = pix[m, p], True
                expected[p].add((m, s))
    return rig, jnp.asarray(xy), jnp.asarray(mask), {frozenset(v) for v in expected.values()}


def with_garbage(xy, mask, d):
    """``xy`` and ``d`` with NaN / huge values in every padded entry."""
    xy = jnp.where(mask[..., None], xy, jnp.asarray(np.nan, xy.dtype))
    pad = ~(mask[:, :, None, None] & mask[None, None])
    junk = jnp.where((jnp.arange(P) % 2 == 0)[None, None, None, :], jnp.nan, -1e30).astype(d.dtype)
    return xy, jnp.where(pad, junk, d)


def permute_slots(seed, xy, mask):
    """A random permutation of the slots of every view: ``perm[m, new] = old``."""
    rng = np.random.default_rng(seed)
    perm = np.stack([rng.permutation(P) for _ in range(M)])
    view = np.arange(M)[:, None]
    return perm, xy[view, perm], mask[view, perm]


def unpermute(sets, perm) -> set[frozenset]:
    return {frozenset((m, int(perm[m, s])) for m, s in g) for g in sets}


def pair_scores(found: set[frozenset], instance, mask) -> tuple[int, int, int]:
    """``(true pairs found, pairs found, true pairs)`` of same-point detection pairs."""
    truth = truth_sets(instance, mask)

    def pairs(sets):
        return {frozenset((a, b)) for g in sets for a in g for b in g if a < b}

    found_pairs, true_pairs = pairs(found), pairs(truth)
    return len(found_pairs & true_pairs), len(found_pairs), len(true_pairs)


def conformance(fn, options, *, bound_scale: float = 1.0, seeds=range(8)) -> None:
    """The checks every method passes (see the module docstring of each test file).

    ``bound_scale``: noise-free scenes must be grouped exactly when every pair of
    detections of different points costs at least ``bound_scale · τ``.
    """
    f = jitted(fn, options)
    # Hand-made scene: known answer.
    rig, xy, mask, expected = hand_scene()
    assert min_cross_cost(
        rig, jnp.where(mask[..., None], xy, 0.0), mask, _hand_instance(mask)
    ) >= bound_scale * gate(0.0)
    g, v, st = f(rig, xy, mask, jnp.float32(0.0))
    check_table(g, v, st, mask)
    assert group_sets(g, v) == expected and int(st) == 0

    exact = 0
    for seed in seeds:
        rig, s = random_scene(seed, 0.0)
        g, v, st = f(rig, s.xy, s.mask, jnp.float32(0.0))
        check_table(g, v, st, mask=s.mask)
        if min_cross_cost(rig, s.xy, s.mask, s.instance) >= bound_scale * gate(0.0):
            exact += 1
            assert group_sets(g, v) == truth_sets(s.instance, s.mask), f"seed {seed}"
    assert exact >= len(seeds) // 2, "too few scenes meet the bound: the check says little"

    # jit == eager, vmap == loop, garbage in padding, slot permutation; noisy scenes.
    rig, s0 = random_scene(100, 3.0)
    _, s1 = random_scene(101, 1.0)
    sig = jnp.float32(3.0)
    want = [f(rig, s.xy, s.mask, sig) for s in (s0, s1)]
    eager = run(fn, options, rig, s0.xy, s0.mask, sig)
    for a, b in zip(eager, want[0]):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    batch = vmapped(fn, options)(rig, jnp.stack([s0.xy, s1.xy]), jnp.stack([s0.mask, s1.mask]), sig)
    for k in range(2):
        for a, b in zip(batch, want[k]):
            np.testing.assert_array_equal(np.asarray(a[k]), np.asarray(b))
    xy_bad, d_bad = with_garbage(s0.xy, s0.mask, distances(rig, s0.xy, s0.mask))
    bad = f(rig, xy_bad, s0.mask, sig, d_bad)
    for a, b in zip(bad, want[0]):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    perm, xy_p, mask_p = permute_slots(7, np.asarray(s0.xy), np.asarray(s0.mask))
    g, v, st = f(rig, jnp.asarray(xy_p), jnp.asarray(mask_p), sig)
    check_table(g, v, st, mask_p)
    assert unpermute(group_sets(g, v), perm) == group_sets(*want[0][:2])


def _hand_instance(mask):
    inst = np.full((M, P), -1)
    for m, slots in HAND_SLOTS.items():
        for p, s in enumerate(slots):
            if s >= 0:
                inst[m, s] = p
    return jnp.asarray(inst)
