"""Seeding from two-view hypotheses (refine/_seed.py) and nearest-point re-assignment with
merging (refine/_reassign.py) on small noise-free scenes whose answer is known."""

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import random_scene, ring_rig

from cdog_jax import Config
from cdog_jax.cdog._stage import GroupTable, Scene, State
from cdog_jax.geometry._epipolar import epipolar_distances
from cdog_jax.geometry._triangulate import dlt_blocks
from cdog_jax.graph._groups import compact_groups
from cdog_jax.refine import _reassign
from cdog_jax.refine._attach import leftover_nodes
from cdog_jax.refine._fit import fit_groups
from cdog_jax.refine._reassign import ReassignOptions, merge_split_groups, reassign_stage
from cdog_jax.refine._seed import SeedOptions, seed_stage

RIG = ring_rig(4)
P = 12


def _scene(sigma=0.0, seed=3, two_view=(), num_points=10, capacity=P, **numbers):
    """A 10-point scene on 4 views (every point in all 4); the points ``two_view`` keep only
    their detections in views 0 and 1 (views 2 and 3 see them, and miss them)."""
    xy, mask, inst, _ = random_scene(RIG, num_points, capacity, sigma=sigma, seed=seed)
    mask[2:] &= ~np.isin(inst[2:], two_view)
    inst = np.where(mask, inst, -1)
    xy, mask = jnp.asarray(xy, jnp.float32), jnp.asarray(mask)
    thresholds = Config.best(**numbers).thresholds(1.0)
    thresholds = thresholds._replace(**{k: jnp.asarray(v) for k, v in thresholds._asdict().items()})
    tau = jnp.asarray(2.0 * np.sqrt(2.0), jnp.float32)  # τ at σ = 1 px
    scene = Scene(
        RIG,
        xy,
        mask,
        mask.reshape(-1),
        epipolar_distances(RIG, xy, mask),
        dlt_blocks(RIG, xy),
        jnp.asarray(1.0, jnp.float32),
        tau,
        thresholds,
    )
    return scene, inst


def _truth(inst, mask):
    """The true group table ``(G, M)``: row k holds instance k's slot in every view."""
    M, capacity = mask.shape
    G = M * capacity // 2
    groups = np.full((G, M), -1, np.int32)
    for m in range(M):
        for i in np.flatnonzero(np.asarray(mask[m])):
            groups[inst[m, i], m] = i
    valid = (groups >= 0).sum(axis=1) >= 2
    groups[~valid] = -1
    return groups, valid


def _partition(table, M):
    """The groups as a set of frozensets of (view, slot)."""
    groups, valid = np.asarray(table.groups), np.asarray(table.valid)
    return {
        frozenset((m, int(g[m])) for m in range(M) if g[m] >= 0) for g, v in zip(groups, valid) if v
    }


def _empty(M):
    G = M * P // 2
    return GroupTable(jnp.full((G, M), -1, jnp.int32), jnp.zeros((G,), bool))


def test_seeding_finds_every_point_of_a_noise_free_scene():
    scene, inst = _scene()
    state = seed_stage(scene, State(_empty(4), None, jnp.int32(0)), SeedOptions(2))
    truth = _truth(inst, scene.mask)
    assert _partition(state.table, 4) == _partition(GroupTable(*truth), 4)


def test_seeding_leaves_the_groups_it_is_given_and_uses_only_free_detections():
    # Views 2 and 3 miss points 8 and 9: seeding refuses such pairs unless any detection
    # explains a view (a radius of 10⁶ τ here; the default is tested below).
    scene, inst = _scene(two_view=(8, 9), seed_support_frac=1e6)
    groups, valid = _truth(inst, scene.mask)
    kept = np.arange(len(valid)) < 4  # the first 4 points stay; the rest are left over
    given = GroupTable(
        jnp.asarray(np.where((valid & kept)[:, None], groups, -1)), jnp.asarray(valid & kept)
    )
    state = seed_stage(scene, State(given, None, jnp.int32(0)), SeedOptions(2))
    assert _partition(given, 4) <= _partition(state.table, 4)
    assert _partition(state.table, 4) == _partition(
        GroupTable(jnp.asarray(groups), jnp.asarray(valid)), 4
    )
    # 3-member seeds only: the 2-view points 8 and 9 stay unassigned, the others are found.
    three = seed_stage(scene, State(given, None, jnp.int32(0)), SeedOptions(3))
    new = _partition(three.table, 4) - _partition(given, 4)
    assert len(new) == 4 and all(len(g) == 4 for g in new)
    # best()'s radius (1.5 τ): the pairs of points 8 and 9 are refused, the others found.
    strict, _ = _scene(two_view=(8, 9))
    state = seed_stage(strict, State(given, None, jnp.int32(0)), SeedOptions(2))
    assert _partition(state.table, 4) == _partition(three.table, 4)


def _split_and_swap(groups, valid, swap):
    """The true table with one 4-view point split over views {0, 1} and {2, 3} (into a free
    row), and, with ``swap``, the view-0 members of two other 4-view points exchanged."""
    big = [g for g in np.flatnonzero(valid) if (groups[g] >= 0).sum() == 4]
    assert len(big) >= 3
    a, b, c = big[:3]
    wrong = groups.copy()
    if swap:
        wrong[a, 0], wrong[b, 0] = groups[b, 0], groups[a, 0]
    free = int(np.flatnonzero(~valid)[0])
    wrong[free, 2:], wrong[c, 2:] = groups[c, 2:], -1
    table = GroupTable(jnp.asarray(wrong), jnp.asarray(valid | (np.arange(len(valid)) == free)))
    assert _partition(table, 4) != _partition(
        GroupTable(jnp.asarray(groups), jnp.asarray(valid)), 4
    )
    return table, c, free


def test_merging_joins_a_point_split_over_disjoint_views():
    scene, inst = _scene()
    groups, valid = _truth(inst, scene.mask)
    table, c, free = _split_and_swap(groups, valid, swap=False)
    X = fit_groups(scene, table).X
    merged = merge_split_groups(scene, table, X, 2.0 * scene.tau)
    np.testing.assert_array_equal(
        np.asarray(merged.groups)[c], groups[c]
    )  # the equal-sized later row moves
    assert not bool(merged.valid[free]) and (np.asarray(merged.groups)[free] == -1).all()
    truth = _partition(GroupTable(jnp.asarray(groups), jnp.asarray(valid)), 4)
    assert _partition(merged, 4) == truth
    # A narrower gate than the points' distances to the members: nothing moves.
    assert _partition(merge_split_groups(scene, table, X, jnp.float32(0.0)), 4) == _partition(
        table, 4
    )


def test_reassignment_detaches_wrong_members_and_seeding_again_restores_them():
    scene, inst = _scene()
    groups, valid = _truth(inst, scene.mask)
    table, _, _ = _split_and_swap(groups, valid, swap=True)
    state = reassign_stage(scene, State(table, None, jnp.int32(0)), ReassignOptions(2))
    truth = _partition(GroupTable(jnp.asarray(groups), jnp.asarray(valid)), 4)
    after = _partition(state.table, 4)
    assert after < truth  # every group left is a true one; the swapped points are detached
    assert state.fit is None
    again = seed_stage(scene, state, SeedOptions(2))
    assert _partition(again.table, 4) == truth


def test_seeding_a_chunk_of_free_detections_at_a_time_is_seeding_at_once(monkeypatch):
    # Above one chunk, the free detections' hypotheses are made and scored a chunk at a
    # time; with chunks of 8 detections (the default; 3 of them here) the seeded groups
    # are those of one pass over all.
    import cdog_jax.refine._seed as seed_module

    scene, inst = _scene(sigma=1.0, seed=5, two_view=(7,))
    groups, valid = _truth(inst, scene.mask)
    kept = np.arange(len(valid)) < 3
    given = GroupTable(
        jnp.asarray(np.where((valid & kept)[:, None], groups, -1)), jnp.asarray(valid & kept)
    )
    start = State(given, None, jnp.int32(0))
    assert int(np.sum(np.asarray(leftover_nodes(*given, scene.mask)))) > 2 * 8
    assert seed_module.SOURCE_CHUNK == 8
    chunked = seed_stage(scene, start, SeedOptions(2)).table
    monkeypatch.setattr(seed_module, "SOURCE_CHUNK", 4 * P)  # every detection's at once
    whole = seed_stage(scene, start, SeedOptions(2)).table
    np.testing.assert_array_equal(np.asarray(chunked.groups), np.asarray(whole.groups))
    np.testing.assert_array_equal(np.asarray(chunked.valid), np.asarray(whole.valid))
    assert len(_partition(whole, 4) - _partition(given, 4)) >= 5  # seeding did find groups


@pytest.mark.parametrize("split_all", [False, True])
def test_a_large_table_measured_a_block_of_rows_at_a_time_gives_the_whole_tables_answer(
    monkeypatch, split_all
):
    # 4 views × 80 slots: 160 group rows, more than twice ROW_BLOCK, so the rounds measure
    # blocks of rows up to the last group. The groups lie scattered over the table, in a
    # noisy scene; one point is split and two swap a member, or (split_all) every point is
    # split over views {0, 1} and {2, 3}: 150-odd groups, so that the last block overlaps
    # the one before it.
    scene, inst = _scene(sigma=2.0, seed=4, num_points=78, capacity=80)
    groups, valid = _truth(inst, scene.mask)
    if split_all:
        free = np.flatnonzero(~valid)
        for g in np.flatnonzero(valid & ((groups[:, :2] >= 0).all(1))):
            if (groups[g, 2:] >= 0).sum() == 2 and len(free):
                groups[free[0], 2:], groups[g, 2:] = groups[g, 2:], -1
                valid[free[0]], free = True, free[1:]
        table = GroupTable(jnp.asarray(groups), jnp.asarray(valid))
        assert int(np.sum(valid)) > 2 * _reassign.ROW_BLOCK
    else:
        table, _, _ = _split_and_swap(groups, valid, swap=True)
    order = np.random.default_rng(0).permutation(len(valid))
    state = State(GroupTable(table.groups[order], table.valid[order]), None, jnp.int32(0))
    assert state.table.groups.shape[0] > 2 * _reassign.ROW_BLOCK
    blocked = reassign_stage(scene, state, ReassignOptions(3)).table
    monkeypatch.setattr(_reassign, "ROW_BLOCK", 10**6)  # the whole table at once
    whole = reassign_stage(scene, state, ReassignOptions(3)).table
    np.testing.assert_array_equal(np.asarray(blocked.groups), np.asarray(whole.groups))
    np.testing.assert_array_equal(np.asarray(blocked.valid), np.asarray(whole.valid))
    assert _partition(whole, 4) != _partition(state.table, 4)  # the rounds changed something


@pytest.mark.parametrize("seed, sigma, rounds_that_change", [(10, 1.0, 3), (3, 2.0, 1)])
def test_the_rounds_stop_at_a_fixed_point_with_the_table_of_every_round_run(
    seed, sigma, rounds_that_change
):
    # reassign_stage stops where a round returns its table unchanged; its table is that of
    # reassign_round applied reassign_iters times, whatever the bound. In the first scene
    # (split and swapped points) three rounds change the table, so a loop that stopped too
    # early differs; in the second only the first does, so the stop is reached.
    scene, inst = _scene(sigma=sigma, seed=seed, num_points=10)
    groups, valid = _truth(inst, scene.mask)
    table, _, _ = _split_and_swap(groups, valid, swap=True)
    gate = scene.thresholds.reassign_frac * scene.tau
    rounds = [table]
    for _ in range(6):
        rounds.append(_reassign.reassign_round(scene, rounds[-1], gate))

    def same(a, b):
        return np.array_equal(np.asarray(a.groups), np.asarray(b.groups)) and np.array_equal(
            np.asarray(a.valid), np.asarray(b.valid)
        )

    assert next(k for k in range(6) if same(rounds[k], rounds[k + 1])) == rounds_that_change
    for iters in (2, 6):  # stopped by the bound (first scene), by the fixed point
        got = reassign_stage(scene, State(table, None, jnp.int32(0)), ReassignOptions(iters))
        want = GroupTable(*compact_groups(rounds[iters].groups, rounds[iters].valid)[:2])
        assert same(got.table, want), iters
