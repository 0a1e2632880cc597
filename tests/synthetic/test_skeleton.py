"""Walking skeletons in a ring of cameras (docs/BENCHMARK.md §7)."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cdog_jax import project
from cdog_jax.synthetic import (
    SKELETON_JOINTS,
    Realism,
    generate_skeleton_scenes,
    ring_rig,
)
from cdog_jax.synthetic._render import CLUTTER, DOUBLE, REAL
from cdog_jax.synthetic._ring import RING_IMAGE_SIZE
from cdog_jax.synthetic._skeleton import (
    HEIGHT_SCALE,
    SKELETON_BONES,
    SKELETON_TEMPLATE,
    skeleton_motion,
)

RIG = ring_rig()
F, K, J = 12, 5, len(SKELETON_JOINTS)


@functools.partial(jax.jit, static_argnames=("max_people",))
def _motion(key, num_people, max_people=K):
    return skeleton_motion(
        key, num_people, max_people=max_people, num_frames=F, fps=10.0, dtype=jnp.float32
    )


def _bone_lengths(joints):
    a, b = np.asarray(SKELETON_BONES).T
    return np.linalg.norm(joints[..., a, :] - joints[..., b, :], axis=-1)


def test_limbs_rigid_and_in_range_over_frames():
    for seed in range(3):
        joints, exists = (np.asarray(a) for a in _motion(jax.random.PRNGKey(seed), 4))
        assert exists.tolist() == [True] * 4 + [False]
        L = _bone_lengths(joints)  # (F, K, bones)
        np.testing.assert_allclose(L, L[:1].repeat(F, axis=0), atol=1e-5)  # rigid over frames
        template = _bone_lengths(SKELETON_TEMPLATE)
        ratio = L / template
        assert (ratio >= HEIGHT_SCALE[0] - 1e-5).all() and (ratio <= HEIGHT_SCALE[1] + 1e-5).all()
        # One scale per person: every bone of a person has the same ratio to the template.
        np.testing.assert_allclose(
            ratio, ratio[..., :1].repeat(ratio.shape[-1], axis=-1), atol=1e-4
        )
        assert (
            np.abs(joints[..., 2].min()) < 0.2 and (joints[..., 2] > 0).all()
        )  # feet near the floor


def test_frames_move_smoothly_and_people_start_apart():
    joints = np.asarray(_motion(jax.random.PRNGKey(7), 5)[0])
    step = np.linalg.norm(np.diff(joints, axis=0), axis=-1)  # (F-1, K, J) metres per 0.1 s
    assert 0.0 < step.max() < 0.35  # ≤ 1 m/s walking plus a swinging wrist
    hips = joints[..., 11:13, :2].mean(axis=-2)  # (F, K, 2)
    assert np.linalg.norm(np.diff(hips, axis=0), axis=-1).max() <= 0.1 + 1e-5  # ≤ 1 m/s
    accel = np.linalg.norm(np.diff(joints, n=2, axis=0), axis=-1)
    assert accel.max() < 0.1  # no jumps
    start = hips[0]
    d = np.linalg.norm(start[:, None] - start[None], axis=-1) + 10 * np.eye(K)
    assert d.min() >= 0.6 - 1e-5


def test_scenes_truth_doubles_and_clutter():
    # The shapes of experiments/robustness_realistic.py --quick (one compile for both).
    sk = generate_skeleton_scenes(
        jax.random.PRNGKey(0),
        RIG,
        5,
        2.0,
        realism=Realism(double_rate=0.3, double_offset_px=2.0, clutter_rate=4.0),
        num_frames=2,
        double_capacity=40,
        clutter_capacity=48,
    )
    fr = sk.frames
    mask, kind, inst, cls, xy = (
        np.asarray(a) for a in (fr.mask, fr.kind, fr.instance, fr.class_id, fr.xy)
    )
    assert xy.shape == (2, RIG.num_views, K * J + 40 + 48, 2)
    real, double, clutter = kind == REAL, kind == DOUBLE, kind == CLUTTER
    assert (
        ((kind == -1) == ~mask).all()
        and (inst[clutter] == -1).all()
        and (inst[real | double] >= 0).all()
    )
    np.testing.assert_array_equal(
        cls[real | double], inst[real | double] % J
    )  # a joint's class is its joint type
    assert ((cls >= 0) & (cls < J)).all()
    np.testing.assert_array_equal(double.sum(axis=2), np.asarray(fr.num_doubles))
    np.testing.assert_array_equal(clutter.sum(axis=2), np.asarray(fr.num_clutter))
    assert (np.asarray(fr.num_doubles) < 40).all()  # never clipped here, so the rate is the draw's
    assert double.sum() / real.sum() == pytest.approx(0.3, abs=0.04)
    assert np.mean(np.asarray(fr.num_clutter)) == pytest.approx(4.0, abs=1.5)
    for f, m, p in zip(*np.nonzero(double)):  # a double sits near its joint's detection
        twin = real[f, m] & (inst[f, m] == inst[f, m, p])
        assert twin.sum() == 1 and np.linalg.norm(xy[f, m, twin][0] - xy[f, m, p]) < 2.0 * 6
    # Real detections lie near the projections of the true joints (σ = 2 px).
    X = np.asarray(sk.joints3d).reshape(2, K * J, 3)
    f, m, p = np.nonzero(real)
    xy_true = np.stack(
        [np.asarray(project(sk.rig, jnp.asarray(X[i]))[0]) for i in range(2)]
    )  # (2, M, I, 2)
    err = np.linalg.norm(xy[f, m, p] - xy_true[f, m, inst[f, m, p]], axis=-1)
    assert np.median(err) < 4.0
    assert (
        real.sum(axis=(1, 2)).min() >= 0.9 * K * J * RIG.num_views
    )  # people near the centre are in view


def _hidden_numpy(K_, R_, t_, joints, exists, image_size, pad=0.1):
    """The box rule of ``hidden_joints`` in float64 NumPy, one frame ``joints (K, J, 3)``."""
    M = K_.shape[0]
    n_people = joints.shape[0]
    out = np.zeros(joints.shape[:2] + (M,), bool)
    for m in range(M):
        cam = joints @ R_[m].T + t_[m]
        depth = cam[..., 2] * np.sign(K_[m, 2, 2])
        uv = cam @ K_[m].T
        xy = uv[..., :2] / uv[..., 2:]
        front = depth > 0
        boxes = {}
        for b in range(n_people):
            if not exists[b] or not front[b].any():
                continue
            lo, hi = xy[b][front[b]].min(0), xy[b][front[b]].max(0)
            boxes[b] = (lo - pad * (hi - lo), hi + pad * (hi - lo), depth[b][front[b]].mean())
        for a in range(n_people):
            for j in range(joints.shape[1]):
                out[a, j, m] = front[a, j] and any(
                    b != a
                    and a in boxes
                    and boxes[b][2] < boxes[a][2]
                    and np.all(boxes[b][0] <= xy[a, j])
                    and np.all(xy[a, j] <= boxes[b][1])
                    for b in boxes
                )
    return out


def test_hidden_joints_against_numpy():
    from cdog_jax.synthetic._skeleton import hidden_joints

    joints, exists = _motion(jax.random.PRNGKey(3), 5)
    K_, R_, t_ = (np.asarray(a, np.float64) for a in (RIG.K, RIG.R, RIG.t))
    total = 0
    for f in range(0, F, 4):
        got = np.asarray(hidden_joints(RIG, joints[f], exists, RING_IMAGE_SIZE))
        want = _hidden_numpy(
            K_, R_, t_, np.asarray(joints[f], np.float64), np.asarray(exists), RING_IMAGE_SIZE
        )
        np.testing.assert_array_equal(got, want)
        total += int(want.sum())
    assert total > 0  # five people in a ring of cameras hide each other


def _errors_scenes(**rates):
    from cdog_jax.synthetic import KeypointErrors

    return generate_skeleton_scenes(
        jax.random.PRNGKey(1),
        RIG,
        4,
        1.0,
        num_frames=4,
        max_people=K,
        keypoint_errors=KeypointErrors(**rates),
    )


def _real_pairs(frames):
    """{(frame, view, point id)} of the real detections."""
    real = np.asarray(frames.mask & (frames.kind == REAL))
    f, m, s = np.nonzero(real)
    return set(zip(f.tolist(), m.tolist(), np.asarray(frames.instance)[f, m, s].tolist()))


def test_keypoint_errors_miss_hidden_joints_and_swap_sides():
    from cdog_jax.synthetic._skeleton import COCO_MIRROR, hidden_joints

    clean = _errors_scenes()
    everything = _real_pairs(clean.frames)
    hidden = np.stack(
        [
            np.asarray(hidden_joints(clean.rig, clean.joints3d[f], clean.exists, RING_IMAGE_SIZE))
            for f in range(4)
        ]
    )  # (F, K, J, M)
    hidden_pairs = {(f, m, k * J + j) for f, k, j, m in zip(*np.nonzero(hidden))}
    assert hidden_pairs & everything  # some joints in sight are hidden
    # Only the hidden joints go; all of them.
    gone = everything - _real_pairs(_errors_scenes(hidden_miss_rate=1.0).frames)
    assert gone == hidden_pairs & everything
    # Only the joints in sight go; all of them.
    gone = everything - _real_pairs(_errors_scenes(miss_rate=1.0).frames)
    assert gone == everything - hidden_pairs
    # A share of them: 30 % within a few points.
    gone = everything - _real_pairs(_errors_scenes(miss_rate=0.3, hidden_miss_rate=0.3).frames)
    assert abs(len(gone) / len(everything) - 0.3) < 0.04
    # Every detection relabelled as the other side's joint (the nose as itself), in place.
    swapped = _errors_scenes(swap_rate=1.0).frames
    real = np.asarray(swapped.mask & (swapped.kind == REAL))
    joint = np.asarray(swapped.instance)[real] % J
    np.testing.assert_array_equal(np.asarray(swapped.class_id)[real], COCO_MIRROR[joint])
    np.testing.assert_array_equal(np.asarray(swapped.xy), np.asarray(clean.frames.xy))
    # A rate per joint: only the wrists in sight go, all of them.
    wrists = np.where(np.isin(np.arange(J), [9, 10]), 1.0, 0.0)
    gone = everything - _real_pairs(_errors_scenes(miss_rate=wrists).frames)
    assert gone == {p for p in everything - hidden_pairs if p[2] % J in (9, 10)}
    # A hidden rate per joint: only the hidden wrists go, all of them.
    gone = everything - _real_pairs(_errors_scenes(hidden_miss_rate=wrists).frames)
    assert gone and gone == {p for p in hidden_pairs & everything if p[2] % J in (9, 10)}
    with pytest.raises(ValueError, match="swap_rate"):
        _errors_scenes(swap_rate=1.5)
    with pytest.raises(ValueError, match=r"hidden_miss_rate must have shape \(\) or \(17,\)"):
        _errors_scenes(hidden_miss_rate=np.zeros(3))
    with pytest.raises(ValueError, match=r"miss_rate must have shape \(\) or \(17,\)"):
        _errors_scenes(miss_rate=np.zeros(3))
