"""docs/BENCHMARK.md §2 metrics on scenes with missed detections and clutter, hand-built cases.

A ground-truth group is an instance with ≥ 2 *surviving* detections (a dropped detection is
simply absent); clutter (a valid detection of instance -1) votes -1, which never matches;
every unassigned valid detection (clutter, or a point seen once) is a singleton prediction.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cdog_jax._result import Association
from cdog_jax.metrics import scene_metrics
from cdog_jax.synthetic import Scene, default_rig

RIG = default_rig()
M, P = RIG.num_views, 2
metrics = jax.jit(scene_metrics)


def case(detections, labels):
    """``detections``: ``{(view, slot): instance}`` (-1 = clutter); ``labels``: ``{(view,
    slot): group}`` (absent = unassigned). Everything else is padding."""
    inst = -np.ones((M, P), np.int32)
    mask = np.zeros((M, P), bool)
    for (m, i), k in detections.items():
        inst[m, i], mask[m, i] = k, True
    lab = -np.ones((M, P), np.int32)
    G = M * P // 2
    groups = -np.ones((G, M), np.int32)
    for (m, i), g in labels.items():
        lab[m, i], groups[g, m] = g, i
    valid = (groups >= 0).any(1)
    pts = np.zeros((P, 3), np.float32)
    scene = Scene(
        xy=jnp.zeros((M, P, 2)),
        mask=jnp.asarray(mask),
        instance=jnp.asarray(inst),
        points3d=jnp.asarray(pts),
        num_points=jnp.asarray(2, jnp.int32),
        num_clutter=jnp.asarray((mask & (inst < 0)).sum(1).astype(np.int32)),
    )
    assoc = Association(
        labels=jnp.asarray(lab),
        groups=jnp.asarray(groups),
        valid=jnp.asarray(valid),
        points3d=jnp.zeros((G, 3)),
        bpe=jnp.zeros((G,)),
        err_px=jnp.zeros((G,)),
        n_views=jnp.asarray((groups >= 0).sum(1).astype(np.int32)),
        num_groups=jnp.asarray(int(valid.sum()), jnp.int32),
        sigma_px=jnp.asarray(0.0),
        tau_px=jnp.asarray(0.0),
        status=jnp.int32(0),
    )
    return metrics(RIG, assoc, scene)


def check(m, **expected):
    for k, v in expected.items():
        assert float(getattr(m, k)) == pytest.approx(v, abs=1e-6), k


# Instance 0 survives in views 0 and 1 (dropped elsewhere), instance 1 only in view 2 (a
# point seen once after the drops), clutter in view 3.
DET = {(0, 0): 0, (1, 1): 0, (2, 0): 1, (3, 1): -1}


def test_perfect_answer_with_a_lone_point_and_clutter():
    m = case(DET, {(0, 0): 0, (1, 1): 0})
    # One ground-truth group (instance 1 has one detection left); 2 singletons.
    check(m, num_gt_groups=1, num_pred_groups=1, num_unassigned=2, num_err_groups=1)
    check(m, pg_p=1, pg_r=1, pg_f1=1, mp_p=1, mp_r=1, mp_f1=1, mp_iou=1)
    check(m, g_p=1 / 3, g_r=1, g_f1=0.5, g_iou=1 / 3)


def test_lone_point_paired_with_clutter_votes_minus_one():
    m = case(DET, {(0, 0): 0, (1, 1): 0, (2, 0): 1, (3, 1): 1})
    # Group 1 = {instance 1, clutter}: tie → -1, an imperfect group with no ground truth.
    check(m, num_gt_groups=1, num_pred_groups=2, num_unassigned=0, num_err_groups=1)
    check(m, pg_p=0.5, pg_r=1, pg_f1=2 / 3, mp_p=0.5, mp_r=0.5, mp_f1=0.5)
    check(m, g_p=0.5, g_r=1, g_f1=2 / 3)


def test_clutter_pair_and_survivor_count():
    det = {(0, 0): 0, (1, 0): 0, (2, 0): 0, (4, 0): -1, (5, 0): -1}
    # Group 0 takes 2 of instance 0's 3 surviving detections: recall 2/3 (not 2/k for the
    # k views where the point was visible); group 1 is two clutter detections.
    m = case(det, {(0, 0): 0, (1, 0): 0, (4, 0): 1, (5, 0): 1})
    check(m, num_gt_groups=1, num_pred_groups=2, num_unassigned=1, num_err_groups=1)
    check(m, mp_p=0.5, mp_r=1 / 3, mp_f1=(0.8 + 0.0) / 2, pg_p=0.5, pg_r=1)
    check(m, g_p=1 / 3, g_r=1, g_f1=0.5)


def test_majority_with_a_clutter_member():
    # {0, 0, clutter}: g = 0 with 2 of 3 nodes: a G- match, not a perfect group.
    det = {(0, 0): 0, (1, 0): 0, (2, 1): -1}
    m = case(det, {(0, 0): 0, (1, 0): 0, (2, 1): 0})
    check(m, g_p=1, g_r=1, pg_p=0, pg_r=0, pg_f1=0, mp_p=2 / 3, mp_r=1, mp_f1=0.8)
