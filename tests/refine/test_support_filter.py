"""Visibility-support filter (Config.support_filter, beyond the paper), hand-built cases."""

import jax
import jax.numpy as jnp
import numpy as np
from helpers import project_np, ring_rig

from cdog_jax import Config, associate
from cdog_jax.refine._support import support_keep

RIG = ring_rig(5)  # 5 views around the origin, all see the box near the origin
M, P = 5, 4


def _points():
    return np.array(
        [[0.1, 0.0, 0.1], [-0.2, 0.15, 0.0], [0.05, -0.2, -0.1], [0.2, 0.2, 0.2]], np.float32
    )


def test_support_keep_hand_built():
    X = _points()  # (4, 3), each seen by all 5 views
    pix, seen = project_np(RIG, X)  # (M, 4, 2), (M, 4)
    assert seen.all()
    # Two detections at opposite image corners per view make the detection area the image.
    corners = np.broadcast_to(np.array([[5.0, 5.0], [635.0, 475.0]]), (M, 2, 2))
    xy, mask = np.concatenate([pix, corners], axis=1).astype(np.float32), np.ones((M, P + 2), bool)
    thresholds = Config.paper().thresholds(1.0)
    tau = jnp.asarray(2.0 * np.sqrt(2.0), jnp.float32)
    # group 0: point 0 in all views (nothing missing; the only group with >= 4 members, so
    # the estimated miss rate is 0, floored at support_min_rate = 0.02); group 1: point 1
    # in views 0, 1 only, and the other views do detect it: nothing missing either;
    # group 2: point 2's detections are removed from views 2, 3, 4: 3 missing of 5,
    # P(Bin(5, 0.02) >= 3) ≈ 8e-5 < 0.01: dropped; group 3: point 3 without views 3, 4:
    # P(Bin(5, 0.02) >= 2) ≈ 0.0038: dropped.
    mask[2:, 2] = False
    mask[3:, 3] = False
    member = np.array([[1, 1, 1, 1, 1], [1, 1, 0, 0, 0], [1, 1, 0, 0, 0], [1, 1, 1, 0, 0]], bool)
    valid = np.ones(4, bool)
    args = (
        RIG,
        jnp.asarray(xy),
        jnp.asarray(mask),
        jnp.asarray(X),
        jnp.asarray(member),
        jnp.asarray(valid),
        tau,
    )
    keep = jax.jit(support_keep)(*args, thresholds)
    np.testing.assert_array_equal(np.asarray(keep), [True, True, False, False])
    # At a miss rate of 0.1, 2 misses of 5 are plausible (0.081), 3 are not (0.0086); at 0.3
    # both are (0.47, 0.16); with alpha = 1e-5 both pass too.
    for changes, expected in (
        (dict(support_min_rate=0.1), [True, True, False, True]),
        (dict(support_min_rate=0.3), [True, True, True, True]),
        (dict(support_alpha=1e-5), [True, True, True, True]),
    ):
        th2 = thresholds._replace(**{k: np.float32(v) for k, v in changes.items()})
        np.testing.assert_array_equal(
            np.asarray(support_keep(*args, th2)), expected, err_msg=str(changes)
        )
    # The miss rate is estimated from the groups with >= support_ref_views members: with
    # every group as a reference (ref views 2), q = 5 / 17 and nothing is dropped.
    th3 = thresholds._replace(support_ref_views=np.float32(2.0))
    np.testing.assert_array_equal(np.asarray(support_keep(*args, th3)), [True, True, True, True])
    # A point behind a member camera is dropped whatever alpha; an invalid group stays invalid.
    behind = X.copy()
    cam0 = -np.asarray(RIG.R)[0].T @ np.asarray(RIG.t)[0]
    behind[0] = cam0 - 1.0 * np.asarray(RIG.R)[0][2]  # 1 unit behind camera 0 along its axis
    keep = support_keep(
        RIG,
        jnp.asarray(xy),
        jnp.asarray(mask),
        jnp.asarray(behind),
        jnp.asarray(member),
        jnp.asarray([True, False, True, True]),
        tau,
        thresholds._replace(support_alpha=np.float32(1e-5)),
    )
    np.testing.assert_array_equal(np.asarray(keep), [False, False, True, True])


def test_pipeline_drops_a_two_view_ghost():
    # Four real points seen by all views, plus a "ghost": two detections in views 0 and 1
    # at the projections of a 3D point that views 2-4 also see but do not detect (what a
    # clutter pair consistent with the epipolar geometry looks like). paper() keeps the
    # pair as a group; with the support filter it is left unassigned, the rest unchanged.
    X = _points()
    ghost = np.array([0.0, 0.0, 0.0], np.float32)  # inside every view's detection area
    xy = np.zeros((M, P + 1, 2), np.float32)
    mask = np.zeros((M, P + 1), bool)
    xy[:, :P], seen = project_np(RIG, X)
    assert seen.all()
    mask[:, :P] = True
    ghost_xy, ghost_seen = project_np(RIG, ghost[None])
    assert ghost_seen.all()
    xy[:2, P] = ghost_xy[:2, 0]
    mask[:2, P] = True
    base = associate(RIG, xy, mask, method=Config.paper(), sigma=1.0)
    filt = associate(RIG, xy, mask, method=Config.paper(support_filter=True), sigma=1.0)
    lb, lf = np.asarray(base.labels), np.asarray(filt.labels)
    assert int(base.num_groups) == 5 and lb[0, P] >= 0 and lb[0, P] == lb[1, P]
    assert int(filt.num_groups) == 4 and lf[0, P] == lf[1, P] == -1
    np.testing.assert_array_equal(lf[:, :P] >= 0, True)
    for i in range(P):  # the real points: one group each, all views
        assert len(set(lf[:, i])) == 1


def test_seeding_allows_the_misses_the_scene_miss_rate_makes_plausible():
    """Seeding's test of the views that see a two-view point with no detection near: none
    allowed without a miss rate (or a NaN one: the filter has not run); with one, the
    filter's binomial test, P(Bin(n + k, q) ≥ k) ≥ alpha, against the plain formula."""
    import itertools
    import math

    from cdog_jax.refine._seed import SeedSupport

    rows = list(itertools.product(range(2, 5), range(0, 4)))  # (members n, missing k)
    count = jnp.asarray([n for n, _ in rows], jnp.int32)
    missing = jnp.asarray([[v < k for v in range(M + 2)] for _, k in rows])  # (R, 7 views)
    alpha = jnp.float32(0.07)
    radius = jnp.float32(3.0)
    none = np.asarray([k == 0 for _, k in rows])
    for q in (None, jnp.float32(jnp.nan)):
        got = jax.jit(lambda m, c, q=q: SeedSupport(radius, q, alpha).plausible(m, c))
        np.testing.assert_array_equal(np.asarray(got(missing, count)), none)
    for q in (0.02, 0.1, 0.3):
        got = SeedSupport(radius, jnp.float32(q), alpha).plausible(missing, count)
        tail = [
            sum(math.comb(n + k, j) * q**j * (1 - q) ** (n + k - j) for j in range(k, n + k + 1))
            for n, k in rows
        ]
        expected = none | (np.asarray(tail) >= 0.07)
        np.testing.assert_array_equal(np.asarray(got), expected, err_msg=str(q))
    # At the floor rate a pair with one missing view is refused, at a 10 % rate kept.
    assert not bool(SeedSupport(radius, jnp.float32(0.02), alpha).plausible(missing, count)[1])
    assert bool(SeedSupport(radius, jnp.float32(0.1), alpha).plausible(missing, count)[1])
    # Members and missing views counted over more views than there are (a voter's view
    # missing too, with a support radius below the vote gate): at most every view.
    over = SeedSupport(radius, jnp.float32(0.12), alpha).plausible(
        missing[-1:], jnp.asarray([6], jnp.int32)
    )  # 6 members, 3 missing views of 7: P(Bin(7, q) ≥ 3) ≈ 0.04 (of 9 views, 0.08)
    tail = sum(math.comb(7, j) * 0.12**j * 0.88 ** (7 - j) for j in range(3, 8))
    assert tail < 0.07 and not bool(over[0])
