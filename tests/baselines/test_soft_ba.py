"""Bundle adjustment with soft matching: conformance, and what the annealing adds.

Noise-free bound: as for triangulation voting, every point seen in ≥ 2 views is grouped
exactly when every pair of detections of different points has symmetric epipolar cost
≥ ``reprojection_gate · τ``. Voting then seeds each true point exactly; a detection of
another point lies at least that far from the point's reprojection in its view, so its
soft assignment at the last temperature (``≈ 0.35 τ``) is below ``e^-16`` of the true
detection's, the re-estimated points stay on the true ones, and the hardening gate
(``reprojection_gate · τ``) admits exactly the point's own detections.
"""

import jax.numpy as jnp
import numpy as np
import pytest
from pairwise_baseline_checks import (
    check_table,
    conformance,
    group_sets,
    hand_scene,
    jitted,
    pair_scores,
    random_scene,
    run,
)

from cdog_jax.baselines._soft_ba import SoftBAOptions, soft_ba_groups
from cdog_jax.baselines._voting import VotingOptions, voting_groups
from cdog_jax.synthetic import default_rig


def test_soft_ba_conformance():
    conformance(soft_ba_groups, SoftBAOptions(), bound_scale=SoftBAOptions().reprojection_gate)


def test_soft_assignment_is_a_softassign_with_slack():
    """Rows (points) and columns (detections) of every view sum to at most 1 (the rest is
    slack), ``-inf`` entries stay impossible, and a clear match takes nearly all weight."""
    from cdog_jax.baselines._soft_ba import _soft_assignment

    e = np.array([[[0.1, 3.0, np.inf]], [[2.5, 0.2, 4.0]]], np.float32)  # (G=2, M=1, P=3) px
    log_aff = jnp.where(
        jnp.isfinite(e), -0.5 * jnp.asarray(np.where(np.isfinite(e), e, 0.0)) ** 2, -jnp.inf
    )
    w = np.exp(np.asarray(_soft_assignment(log_aff, jnp.float32(-2.0), 50)))
    assert np.all(w.sum(axis=2) <= 1 + 1e-5) and np.all(w.sum(axis=0) <= 1 + 1e-5)
    assert w[0, 0, 2] == 0.0
    assert w[0, 0, 0] > 0.8 and w[1, 0, 1] > 0.8 and w[1, 0, 2] < 0.1


def test_soft_ba_hardening_gate_admits_what_voting_drops():
    """A third-view detection 2.2 px off (σ = 0: τ = 1 px, voting's inlier gate 2 px) is
    left out by voting; soft BA's points, re-estimated from all members, keep it when the
    hardening gate allows it (gate 3 τ)."""
    rig, xy, mask, expected = hand_scene()
    moved = xy.at[2, 1].add(jnp.asarray([0.0, 2.2], xy.dtype))  # point 0 in view 2
    options = SoftBAOptions(reprojection_gate=3.0)
    g, v, st = jitted(soft_ba_groups, options)(rig, moved, mask, jnp.float32(0.0))
    check_table(g, v, st, mask)
    assert group_sets(g, v) == expected and int(st) == 0
    g, v, _ = jitted(voting_groups, VotingOptions())(rig, moved, mask, jnp.float32(0.0))
    assert group_sets(g, v) != expected


def test_soft_ba_is_not_worse_than_voting_on_noisy_scenes():
    """Summed over noisy scenes, the pairwise F1 of soft BA is at least voting's (it starts
    from voting's groups and re-assigns)."""
    f_soft, f_vote = jitted(soft_ba_groups, SoftBAOptions()), jitted(voting_groups, VotingOptions())
    totals = np.zeros((2, 3))
    for seed in range(6):
        rig, s = random_scene(200 + seed, 2.0)
        for k, f in enumerate((f_soft, f_vote)):
            g, v, st = f(rig, s.xy, s.mask, jnp.float32(2.0))
            check_table(g, v, st, s.mask)
            totals[k] += pair_scores(group_sets(g, v), s.instance, s.mask)
    f1 = 2 * totals[:, 0] / (totals[:, 1] + totals[:, 2])
    assert f1[0] >= f1[1] - 1e-9, f1


def test_soft_ba_options_checked():
    for name in ("rounds", "sinkhorn_iterations"):
        for bad in (0, -2, True):
            with pytest.raises(ValueError, match=name):
                SoftBAOptions(**{name: bad})
    for name in SoftBAOptions.THRESHOLDS:
        for bad in (0.0, -1.0, float("nan")):
            with pytest.raises(ValueError, match=name):
                SoftBAOptions(**{name: bad})


def test_soft_ba_single_view_has_no_groups():
    rig = default_rig(num_views=1)
    g, v, st = run(
        soft_ba_groups,
        SoftBAOptions(),
        rig,
        jnp.zeros((1, 4, 2), jnp.float32),
        jnp.ones((1, 4), bool),
        1.0,
    )
    assert g.shape == (2, 1) and not np.asarray(v).any() and int(st) == 0
