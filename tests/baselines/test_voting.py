"""Triangulation voting: conformance, and inliers taken by reprojection.

Noise-free bound: every point seen in ≥ 2 views is grouped exactly when every pair of
detections of different points has symmetric epipolar cost ≥ ``reprojection_gate · τ``
(and ≥ τ, which that implies for a gate ≥ 1). Then every hypothesis is a same-point pair
whose two-view point is the true point; the point's own detection in a third view
reprojects within round-off, and any other detection within ``reprojection_gate · τ`` of
that reprojection would lie that close to both epipolar lines, i.e. cost less than the
gate, which the bound excludes.
"""

import jax.numpy as jnp
import numpy as np
import pytest
from pairwise_baseline_checks import check_table, conformance, group_sets, hand_scene, jitted, run

from cdog_jax.baselines._voting import VotingOptions, voting_groups
from cdog_jax.geometry import project
from cdog_jax.synthetic import default_rig


def test_voting_conformance():
    conformance(voting_groups, VotingOptions(), bound_scale=VotingOptions().reprojection_gate)


def test_voting_third_view_joins_by_reprojection():
    """A detection moved off its point's reprojection by more than the gate leaves the
    group (it is seen by no hypothesis: its epipolar cost is too large too), one moved by
    less stays."""
    rig, xy, mask, expected = hand_scene()
    f = jitted(voting_groups, VotingOptions())
    moved = xy.at[2, 1].add(jnp.asarray([0.0, 1.5], xy.dtype))  # point 0 in view 2, 1.5 px off
    g, v, st = f(rig, moved, mask, jnp.float32(0.0))
    check_table(g, v, st, mask)
    assert group_sets(g, v) == expected  # 1.5 px < 2 τ = 2 px: still an inlier
    far = xy.at[2, 1].add(jnp.asarray([0.0, 4.0], xy.dtype))
    g, v, _ = f(rig, far, mask, jnp.float32(0.0))
    point0 = next(s for s in expected if (0, 5) in s)
    assert group_sets(g, v) == (expected - {point0}) | {point0 - {(2, 1)}}
    assert np.asarray(st) == 0


def test_voting_uses_each_detection_once():
    """Point B lies on view 2's ray through point A and is not seen by view 2, so every
    hypothesis reprojects into view 2 onto A's detection (or holds it): whichever is
    accepted first takes it, and the other group must do without."""
    rig, _, _, _ = hand_scene()
    centre = np.asarray(rig.centers)[2]
    A = np.zeros(3)
    B = A + 0.3 * (A - centre) / np.linalg.norm(A - centre)
    pix, front = project(rig, jnp.asarray(np.stack([A, B]), rig.K.dtype))
    assert np.asarray(front)[:3].all()
    xy = np.zeros((4, 12, 2), np.float32)
    mask = np.zeros((4, 12), bool)
    slots = {(0, 0): 3, (1, 0): 7, (2, 0): 1, (0, 1): 10, (1, 1): 2}  # (view, point) → slot
    for (m, p), s in slots.items():
        xy[m, s], mask[m, s] = np.asarray(pix)[m, p], True
    f = jitted(voting_groups, VotingOptions())
    g, v, st = f(rig, jnp.asarray(xy), jnp.asarray(mask), jnp.float32(0.0))
    check_table(g, v, st, mask)
    found = group_sets(g, v)
    assert len(found) == 2 and set().union(*found) == {(m, s) for (m, _), s in slots.items()}


def test_voting_options_checked():
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="reprojection_gate"):
            VotingOptions(reprojection_gate=bad)


def test_voting_single_view_has_no_groups():
    rig = default_rig(num_views=1)
    g, v, st = run(
        voting_groups,
        VotingOptions(),
        rig,
        jnp.zeros((1, 4, 2), jnp.float32),
        jnp.ones((1, 4), bool),
        1.0,
    )
    assert g.shape == (2, 1) and not np.asarray(v).any() and int(st) == 0


def test_voting_fills_every_row_when_every_detection_pairs_up():
    """Two views, every slot a detection of a point both see: N // 2 groups, every row of
    the table, and the loop's bound (the table's rows) ends nothing early."""
    rig = default_rig(num_views=2)
    rng = np.random.default_rng(3)
    points = []
    while len(points) < 6:  # points both views see, inside the image
        X = rng.uniform(-0.8, 0.8, 3)
        pix, front = project(rig, jnp.asarray(X[None], rig.K.dtype))
        pix = np.asarray(pix)[:, 0]
        if np.asarray(front).all() and ((pix > 20) & (pix < [620, 460])).all():
            points.append(pix)
    xy = np.stack(points, axis=1).astype(np.float32)  # (2, 6, 2)
    mask = np.ones((2, 6), bool)
    g, v, st = run(voting_groups, VotingOptions(), rig, jnp.asarray(xy), jnp.asarray(mask), 0.0)
    check_table(g, v, st, mask)
    assert np.asarray(v).shape == (6,) and np.asarray(v).all()
    assert group_sets(g, v) == {frozenset({(0, k), (1, k)}) for k in range(6)}
