"""Loops that stop at their bound say so in Association.status, per scene under a batch."""

import numpy as np
import pytest
from helpers import random_scene, ring_rig

from cdog_jax import Config, Status, associate_batch, check_status, status_messages
from cdog_jax._method import Observations

RIG = ring_rig(5)
# Scene 0: ten points in a small box with clutter and σ = 4 px (components with several
# view conflicts, groups with outliers); scene 1: two clean points (nothing to split or clean).
_A = random_scene(RIG, 10, 12, sigma=4.0, seed=0, clutter=2, box=0.2)
_B = random_scene(RIG, 2, 12, sigma=0.5, seed=4)
XY, MASK = np.stack([_A[0], _B[0]]), np.stack([_A[1], _B[1]])


def _status(config):
    return [
        int(s)
        for s in np.asarray(
            associate_batch(RIG, XY, MASK, method=config, sigma=4.0, batch_size=2).status
        )
    ]


def test_a_loop_stopped_at_its_bound_sets_its_flag_per_scene():
    split = _status(Config.reference(max_split_iters=1))
    assert split == [Status.SPLIT_CAPPED, 0]
    iqr_refine = _status(Config.reference(max_iqr_iters=1, refine=True, refine_max_steps=1))
    assert iqr_refine[0] & Status.IQR_CAPPED and not iqr_refine[1] & Status.IQR_CAPPED
    assert iqr_refine[1] == Status.REFINE_CAPPED  # two clean groups: one LM step is not enough
    default = _status(Config.reference(refine=True))
    assert default[0] & (Status.SPLIT_CAPPED | Status.IQR_CAPPED) == 0 and default[1] == 0
    with pytest.raises(
        RuntimeError, match="scene 0: the view-uniqueness split stopped at its iteration bound"
    ):
        check_status(split)
    assert len(status_messages(split[0])) == 1 and status_messages(0) == []


def test_a_lens_that_cannot_be_inverted_is_flagged_per_scene():
    """Detections a lens model cannot have produced (k1 = −5 folds the image inside these
    views: no ideal pixel distorts onto their outer detections) raise LENS_NOT_INVERTED in
    that scene only; an invertible lens raises nothing."""
    from cdog_jax.geometry._distortion import _folded

    folding = np.zeros((5, 5), np.float32)
    folding[:, 0] = -5.0
    mild = np.zeros((5, 5), np.float32)
    mild[:, 0] = -0.05
    for dist, expected in ((folding, Status.LENS_NOT_INVERTED), (mild, 0)):
        status = associate_batch(RIG, XY, MASK, sigma=4.0, dist=dist, batch_size=2).status
        assert [int(s) & Status.LENS_NOT_INVERTED for s in np.asarray(status)] == [expected] * 2
    assert "could not be inverted" in status_messages(Status.LENS_NOT_INVERTED)[0]
    # The radial model turns back at r² = 1 / 15 for k1 = −5: beyond it, two ideal points
    # share a detection.
    r = np.array([[0.2, 0.25, 0.26, 0.4]], np.float32)
    folded = np.asarray(_folded(folding[:1], r, np.zeros_like(r)))
    assert folded.tolist() == [[False, False, True, True]]


@pytest.mark.parametrize("method", ["best", "greedy"])
def test_a_non_finite_detection_under_jit_is_left_out_and_said(method):
    """NaN or inf in one valid slot, inside the user's own jit (no input checks there): the
    detection leaves its group, every other group is unchanged, NONFINITE_DETECTION is set."""
    import jax

    from cdog_jax import method_from

    m = method_from(method, "test")
    thresholds = m.thresholds(0.5)
    xy, mask, _, _ = random_scene(RIG, 8, 10, sigma=0.5, seed=3)
    run = jax.jit(lambda xy, mask: m.associate_scene(RIG, Observations(xy, mask), thresholds))
    before = run(xy, mask)
    groups = np.asarray(before.groups)[np.asarray(before.valid)]
    view, slot = 1, int(groups[groups[:, 1] >= 0][0, 1])
    for bad in (np.nan, np.inf):
        poisoned = np.array(xy)
        poisoned[view, slot] = bad
        after = run(poisoned, mask)
        expected = {
            tuple(int(s) if (v, s) != (view, slot) else -1 for v, s in enumerate(g)) for g in groups
        }
        got = {tuple(map(int, g)) for g in np.asarray(after.groups)[np.asarray(after.valid)]}
        assert got == {g for g in expected if sum(s >= 0 for s in g) >= 2}
        assert int(after.status) & Status.NONFINITE_DETECTION
        assert np.isfinite(np.asarray(after.points3d)[np.asarray(after.valid)]).all()
    assert not int(before.status) & Status.NONFINITE_DETECTION
