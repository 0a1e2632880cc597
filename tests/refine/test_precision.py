"""The precision rules of best(): seeding refuses a two-view hypothesis that a third view
sees with no detection near (refine/_seed.py), and a group detaches a member that another
detection of its view fits as well (refine/_ambiguity.py); hand-built scenes."""

import jax.numpy as jnp
import numpy as np
from helpers import project_np, ring_rig

from cdog_jax import Config
from cdog_jax.cdog._stage import GroupTable, Scene, State
from cdog_jax.geometry._epipolar import epipolar_distances
from cdog_jax.geometry._triangulate import dlt_blocks
from cdog_jax.refine._ambiguity import AMBIGUITY, ambiguity_stage
from cdog_jax.refine._fit import fit_groups
from cdog_jax.refine._seed import SeedOptions, seed_stage

RIG = ring_rig(4)
M, P = 4, 4
SIGMA = 1.0
TAU = 2.0 * np.sqrt(2.0) * SIGMA
CORNERS = np.array(
    [[5.0, 5.0], [635.0, 475.0]]
)  # slots 0 and 1 of every view: the detection area is the image


def _scene(xy, mask):
    xy, mask = jnp.asarray(xy, jnp.float32), jnp.asarray(mask)
    thresholds = Config.best().thresholds(SIGMA)
    thresholds = thresholds._replace(**{k: jnp.asarray(v) for k, v in thresholds._asdict().items()})
    return Scene(
        RIG,
        xy,
        mask,
        mask.reshape(-1),
        epipolar_distances(RIG, xy, mask),
        dlt_blocks(RIG, xy),
        jnp.asarray(SIGMA, jnp.float32),
        jnp.asarray(TAU, jnp.float32),
        thresholds,
    )


def _layout():
    """``xy (M, P, 2)`` with the two corner detections in every view, an empty ``mask``
    beyond them, and the given groups: one row per corner (they take the corners away from
    seeding)."""
    xy = np.zeros((M, P, 2))
    xy[:, :2] = CORNERS
    mask = np.zeros((M, P), bool)
    mask[:, :2] = True
    groups = np.full((M * P // 2, M), -1, np.int32)
    groups[0], groups[1] = 0, 1
    return xy, mask, groups


def _partition(table):
    groups, valid = np.asarray(table.groups), np.asarray(table.valid)
    return {
        frozenset((m, int(g[m])) for m in range(M) if g[m] >= 0) for g, v in zip(groups, valid) if v
    }


def test_seeding_refuses_a_pair_whose_point_other_views_see_without_a_detection():
    A = np.array([0.1, 0.0, 0.1])
    centre0 = -np.asarray(RIG.R[0], np.float64).T @ np.asarray(RIG.t[0], np.float64)
    C = A + 0.4 * (A - centre0)  # on view 0's line of sight through A: an epipolar match in view 1
    pix, seen = project_np(RIG, np.stack([A, C]))  # (M, 2, 2)
    assert seen[:, 1].all()
    for m in (2, 3):  # C lands in the detection area of views 2 and 3, far from the corners
        assert np.min(np.linalg.norm(CORNERS - pix[m, 1], axis=1)) > 10 * TAU
    xy, mask, groups = _layout()
    xy[0, 2], xy[1, 2] = pix[0, 0], pix[1, 1]  # A's detection in view 0, C's in view 1: free
    mask[[0, 1], 2] = True
    given = GroupTable(jnp.asarray(groups), jnp.asarray((groups >= 0).any(axis=1)))
    pair = frozenset({(0, 2), (1, 2)})

    # Views 2 and 3 see C and hold nothing near it: no group.
    state = seed_stage(_scene(xy, mask), State(given, None, jnp.int32(0)), SeedOptions(2))
    assert _partition(state.table) == _partition(given)

    # A detection 1 px from C in views 2 and 3 (taken by a given group: no vote) explains
    # them: the pair is seeded.
    xy[2:, 2] = pix[2:, 1] + np.array([1.0, 0.0])
    mask[2:, 2] = True
    groups[2, 2:] = 2
    given = GroupTable(jnp.asarray(groups), jnp.asarray((groups >= 0).any(axis=1)))
    state = seed_stage(_scene(xy, mask), State(given, None, jnp.int32(0)), SeedOptions(2))
    assert _partition(state.table) == _partition(given) | {pair}


def _ambiguous_case(offset_px):
    """Point A in views 0–2 and, in view 3, a neighbour's detection 1 px from A's projection
    in the group, A's own detection ``offset_px`` from it left free."""
    A = np.array([-0.1, 0.1, 0.05])
    pix, seen = project_np(RIG, A[None])
    assert seen.all()
    xy, mask, groups = _layout()
    xy[:, 2] = pix[:, 0]
    xy[3, 2] = pix[3, 0] + np.array([1.0, 0.0])  # the neighbour's, in the group
    xy[3, 3] = pix[3, 0] + np.array([offset_px, 0.0])  # A's own, free
    mask[:, 2] = True
    mask[3, 3] = True
    groups[2] = 2
    table = GroupTable(jnp.asarray(groups), jnp.asarray((groups >= 0).any(axis=1)))
    scene = _scene(xy, mask)
    return scene, State(table, fit_groups(scene, table), jnp.int32(0))


def test_a_member_another_detection_fits_as_well_is_detached():
    assert Config.best().detach_ambiguous and AMBIGUITY.when(Config.best())
    scene, state = _ambiguous_case(0.3)  # A's own detection is nearer A's point than the member
    out = ambiguity_stage(scene, state, None)
    np.testing.assert_array_equal(np.asarray(out.table.groups)[2], [2, 2, 2, -1])
    assert bool(out.table.valid[2])
    np.testing.assert_array_equal(np.asarray(out.fit.member)[2], [True, True, True, False])

    # The other detection 3 px away: 2 px farther than the member, beyond 0.1 τ: kept.
    scene, state = _ambiguous_case(3.0)
    out = ambiguity_stage(scene, state, None)
    np.testing.assert_array_equal(np.asarray(out.table.groups)[2], [2, 2, 2, 2])
    # A wider margin (0.8 τ ≈ 2.3 px) calls it ambiguous again.
    wide = scene._replace(
        thresholds=scene.thresholds._replace(ambiguous_frac=jnp.asarray(0.8, jnp.float32))
    )
    out = ambiguity_stage(wide, state, None)
    np.testing.assert_array_equal(np.asarray(out.table.groups)[2], [2, 2, 2, -1])
