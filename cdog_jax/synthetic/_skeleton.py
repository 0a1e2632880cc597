"""Scenes of walking people (docs/BENCHMARK.md §7): ``K`` skeletons of the 17 COCO joints, each joint
type a class, over ``F`` frames, rendered with the :class:`Realism` options.

A person is the template below (metres, standing, facing +x, feet on ``z = 0``) scaled by a
height factor, with arms and legs swinging about the shoulders and hips (rigid limbs: the
bone lengths of a person never change), walking on the floor with a slowly turning heading.
The output is what :func:`cdog_jax.associate_classes` takes, frame by frame.
"""

from __future__ import annotations

import functools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, PRNGKeyArray, Real

from .._expect import ARRAY, expect_args
from .._types import Array, Bool, Float, Int
from ..geometry._camera import Rig
from ..geometry._projection import project_views_last
from ..io._keypoints import SKELETONS
from ._realism import Realism, perturb_rig, view_sigmas
from ._render import REAL, RealScene, render_points
from ._ring import RING_IMAGE_SIZE

SKELETON_JOINTS: tuple[str, ...] = SKELETONS["COCO_17"]
"""The joint classes, in COCO-17 keypoint order (the names OpenPose readers use)."""

SKELETON_TEMPLATE = np.array(
    [
        [0.10, 0.00, 1.62],
        [0.08, 0.03, 1.66],
        [0.08, -0.03, 1.66],
        [0.00, 0.075, 1.63],
        [0.00, -0.075, 1.63],
        [0.00, 0.19, 1.45],
        [0.00, -0.19, 1.45],
        [0.00, 0.21, 1.17],
        [0.00, -0.21, 1.17],
        [0.02, 0.22, 0.92],
        [0.02, -0.22, 0.92],
        [0.00, 0.10, 0.95],
        [0.00, -0.10, 0.95],
        [0.02, 0.11, 0.52],
        [0.02, -0.11, 0.52],
        [0.00, 0.11, 0.08],
        [0.00, -0.11, 0.08],
    ]
)
"""``(17, 3)`` joint positions (metres) of a 1.7 m person: upper arm 0.28 m, forearm 0.25 m,
thigh 0.43 m, shin 0.44 m, shoulders 0.38 m apart."""

SKELETON_BONES: tuple[tuple[int, int], ...] = (
    (5, 7),
    (7, 9),
    (6, 8),
    (8, 10),
    (11, 13),
    (13, 15),
    (12, 14),
    (14, 16),
    (5, 6),
    (11, 12),
    (5, 11),
    (6, 12),
    (0, 1),
    (0, 2),
    (1, 3),
    (2, 4),
)
"""Joint pairs whose distance is a bone of the template (fixed for a person)."""

HEIGHT_SCALE = (0.85, 1.15)
"""Range of a person's scale factor of the template (1.45–1.96 m tall)."""

# Swing: joint j turns by SWING_SIGN[j] · θ(t) about the lateral axis through SWING_PIVOT[j]
# (elbows and wrists about their shoulder, knees and ankles about their hip; arms and legs
# in opposition, left and right in opposition).
_SWING_PIVOT = np.array([0, 1, 2, 3, 4, 5, 6, 5, 6, 5, 6, 11, 12, 11, 12, 11, 12])
_SWING_SIGN = np.array([0, 0, 0, 0, 0, 0, 0, 1, -1, 1, -1, 0, 0, -1, 1, -1, 1], np.float64)
_SPEED = (0.3, 1.0)  # m/s
_TURN = 0.6  # max |heading rate|, rad/s
_SWING_DEG = (10.0, 25.0)  # amplitude
_STEP_HZ = (0.7, 1.0)
_GRID_SPACING = (
    1.0  # start positions: distinct cells of a 3 × 3 grid of this spacing (metres), jittered
)
_GRID_JITTER = 0.2


COCO_MIRROR = np.array(
    [
        SKELETON_JOINTS.index(
            name.replace("left", "\0").replace("right", "left").replace("\0", "right")
        )
        for name in SKELETON_JOINTS
    ],
    np.int32,
)
"""The joint of the other side for each COCO-17 joint (the nose is its own)."""

_HIDING_PAD = 0.1  # a person's image box, padded by this share of its size on each side
_MISS, _SWAP = 1001, 1002  # fold_in tags of the keypoint errors (apart from the render's)


def _sides_averaged(limbs: dict[str, float]) -> np.ndarray:
    """``(17,)`` per joint from one number per limb joint type (left and right alike); the
    face, which Shelf's annotation lacks, gets the limbs' mean."""
    face = float(np.mean(list(limbs.values())))
    return np.array([face] * 5 + [rate for rate in limbs.values() for _ in range(2)])


SHELF_MISSED = _sides_averaged(
    {
        "shoulder": 0.0205,
        "elbow": 0.1585,
        "wrist": 0.2185,
        "hip": 0.041,
        "knee": 0.0515,
        "ankle": 0.065,
    }
)
"""``(17,)`` how often Shelf's OpenPose detector misses each joint of an annotated actor in
sight of a camera, hidden by another person or not (dev frames, within 50 px; left and right
averaged):
``experiments/real/shelf_detections.py``."""
SHELF_HIDDEN_RATIO = 0.241 / 0.084
"""How many times more often Shelf's detector misses a joint that another annotated actor
hides (24.1 %) than one that no annotated actor hides (8.4 %)."""
SHELF_HIDDEN_SHARE = 0.218
"""The share of the joints in sight that another person hides in the people scenes seen by
Shelf's cameras (3–5 people; ``experiments/real/shelf_generator_check.py``). Shelf's own
share (5.4 %) counts only its annotated actors as hiders, a lower bound."""
SHELF_MISS_RATE = SHELF_MISSED / (1.0 + (SHELF_HIDDEN_RATIO - 1.0) * SHELF_HIDDEN_SHARE)
"""``(17,)`` :meth:`KeypointErrors.shelf`'s in-sight miss rate of every joint: with
``SHELF_HIDDEN_RATIO`` times it for a hidden joint and the scenes' hidden share, each joint
is missed as often as on Shelf."""


class KeypointErrors(eqx.Module):
    """What a keypoint detector does to people beyond the pixel noise of :class:`Realism`;
    every field a traced number (a sweep over them compiles once). The defaults do nothing.

    Attributes:
        miss_rate: probability in ``[0, 1]`` that a joint in sight of a camera, and hidden
            by no other person, is not detected there: one for every joint, or ``(17,)``,
            one per joint in :data:`SKELETON_JOINTS` order.
        hidden_miss_rate: the same for a joint that another person hides: it lies in the
            image box of that person's joints (padded by 10 %), whose joints are nearer the
            camera on average; one for every joint, or ``(17,)``.
        swap_rate: probability in ``[0, 1]`` that a detected joint is labelled as its
            mirrored joint (left for right; the nose keeps its label).

    :meth:`shelf` gives the rates measured on Shelf's real OpenPose detections.
    """

    miss_rate: float | Float[ArrayLike, "*joints"] = 0.0  # () or (17,): checked below
    hidden_miss_rate: float | Float[ArrayLike, "*joints"] = 0.0  # () or (17,)
    swap_rate: float | Float[Array, ""] = 0.0

    def __check_init__(self):
        # Traced fields (inside jit or vmap) cannot be checked; numbers and NumPy arrays are.
        for name in ("miss_rate", "hidden_miss_rate", "swap_rate"):
            value = getattr(self, name)
            if isinstance(value, (int, float, np.ndarray, list, tuple)):
                v = np.asarray(value, float)
                per_joint = name in ("miss_rate", "hidden_miss_rate")
                allowed = ((), (len(SKELETON_JOINTS),)) if per_joint else ((),)
                if v.shape not in allowed:
                    raise ValueError(
                        f"KeypointErrors.{name} must have shape {' or '.join(map(str, allowed))}"
                        f"; got {v.shape}"
                    )
                if not np.all((v >= 0) & (v <= 1)):
                    raise ValueError(f"KeypointErrors.{name} must be in [0, 1]; got {value!r}")

    @classmethod
    def shelf(cls) -> KeypointErrors:
        """The rates of Shelf's OpenPose detections of its annotated actors (dev frames,
        joints within 50 px of the annotation; experiments/RESULTS.md, "Shelf's detections
        beside its ground truth"), fitted to these scenes: each joint is missed as often as
        Shelf's detector misses it (shoulders 2.1 %, elbows 15.9 %,
        wrists 21.9 %, hips 4.1 %, knees 5.2 %, ankles 6.5 %; the face the limbs' mean),
        a hidden joint 2.9 times as often as one in sight (Shelf's ratio), given the share
        of hidden joints in people scenes seen by Shelf's cameras (21.8 %); 0.5 % swapped."""
        return cls(
            miss_rate=SHELF_MISS_RATE,
            hidden_miss_rate=SHELF_HIDDEN_RATIO * SHELF_MISS_RATE,
            swap_rate=0.005,
        )

    def as_arrays(self, dtype) -> KeypointErrors:
        """The same rates as ``()`` arrays of ``dtype``."""
        return jax.tree_util.tree_map(lambda v: jnp.asarray(v, dtype), self)


def hidden_joints(
    rig: Rig,
    joints: Float[Array, "K J 3"],
    exists: Bool[Array, " K"],
    image_size: tuple[int, int],
) -> Bool[Array, "K J M"]:
    """``(K, J, M)``: joint ``j`` of person ``k`` is hidden in view ``m`` by another existing
    person: it projects into that person's image box (its in-front joints' pixels, padded by
    10 % of the box's size on each side) and that person's joints are nearer the camera on
    average (depth along the optical axis). Joints behind a camera are never hidden."""
    K, J = joints.shape[:2]
    xy, front = project_views_last(rig, joints.reshape(-1, 3))  # (K·J, M, 2), (K·J, M)
    xy, front = xy.reshape(K, J, -1, 2), front.reshape(K, J, -1)
    # Distance along the optical axis (K[2, 2] = -1: the camera looks down -z).
    z = jnp.einsum("mj,kpj->kpm", rig.R[:, 2, :], joints) + rig.t[None, None, :, 2]
    depth = z * jnp.sign(rig.K[None, None, :, 2, 2])  # (K, J, M)
    ok = (front & exists[:, None, None])[..., None]  # (K, J, M, 1)
    lo = jnp.min(jnp.where(ok, xy, jnp.inf), axis=1)  # (K, M, 2)
    hi = jnp.max(jnp.where(ok, xy, -jnp.inf), axis=1)
    pad = _HIDING_PAD * jnp.where(jnp.isfinite(hi - lo), hi - lo, 0.0)
    lo, hi = lo - pad, hi + pad
    count = jnp.sum(ok[..., 0], axis=1, dtype=depth.dtype)
    mean_depth = jnp.sum(jnp.where(ok[..., 0], depth, 0.0), axis=1) / jnp.maximum(count, 1.0)
    inside = jnp.all(
        (xy[:, :, None] >= lo[None, None]) & (xy[:, :, None] <= hi[None, None]), axis=-1
    )  # (K, J, K', M): joint (k, j) in the box of person k'
    nearer = mean_depth[None, :, :] < mean_depth[:, None, :]  # (K, K', M)
    other = ~jnp.eye(K, dtype=bool) & exists[None, :]  # (K, K')
    hiding = inside & (nearer & other[..., None])[:, None] & front[:, :, None]
    return jnp.any(hiding, axis=2)


def detector_errors(
    key: PRNGKeyArray,
    scene: RealScene,
    hidden: Bool[Array, "I M"],
    errors: KeypointErrors,
) -> RealScene:
    """``scene`` with its real detections missed (``errors.miss_rate``, or
    ``hidden_miss_rate`` where ``hidden (I, M)`` says the point is hidden in that view) and
    relabelled as their mirrored COCO-17 joint (``swap_rate``); a missed detection's slot becomes
    padding. Doubles and clutter are left as they are."""
    M, S = scene.mask.shape
    real = scene.mask & (scene.kind == REAL)
    point = jnp.maximum(scene.instance, 0)  # (M, S)
    view = jnp.broadcast_to(jnp.arange(M, dtype=jnp.int32)[:, None], (M, S))
    joint = point % len(COCO_MIRROR)
    in_sight_rate = jnp.broadcast_to(errors.miss_rate, COCO_MIRROR.shape)[joint]
    hidden_rate = jnp.broadcast_to(errors.hidden_miss_rate, COCO_MIRROR.shape)[joint]
    rate = jnp.where(hidden[point, view], hidden_rate, in_sight_rate)
    dtype = rate.dtype
    missed = real & (jax.random.uniform(jax.random.fold_in(key, _MISS), (M, S), dtype) < rate)
    swapped = (
        real
        & ~missed
        & (jax.random.uniform(jax.random.fold_in(key, _SWAP), (M, S), dtype) < errors.swap_rate)
    )
    mirror = jnp.asarray(COCO_MIRROR)
    mask = scene.mask & ~missed
    return eqx.tree_at(
        lambda r: (r.xy, r.mask, r.instance, r.kind, r.class_id),
        scene,
        (
            jnp.where(mask[..., None], scene.xy, 0.0),
            mask,
            jnp.where(mask, scene.instance, -1),
            jnp.where(mask, scene.kind, -1),
            jnp.where(mask, jnp.where(swapped, mirror[scene.class_id], scene.class_id), 0).astype(
                jnp.int32
            ),
        ),
    )


class SkeletonScenes(eqx.Module):
    """``F`` frames of ``K`` people, their detections and the ground truth.

    Attributes:
        frames: a :class:`RealScene` with a leading ``F`` on every field: ``xy (F, M, S, 2)``,
            ``mask``, ``class_id (F, M, S)`` (the joint), ``instance (F, M, S)`` (point id
            ``person · 17 + joint``), ``kind``, ``points3d (F, K·17, 3)``; ``frames.rig`` and
            ``sigma_view`` repeat the same values in every frame.
        joints3d: ``(F, K, 17, 3)`` ground-truth joints (metres).
        exists: ``(K,)`` bool, the person exists (the first ``num_people``).
        rig: the true cameras of the sequence (``M`` views; the method gets the nominal rig).
    """

    frames: RealScene
    joints3d: Float[Array, "F K J 3"]
    exists: Bool[Array, " K"]
    rig: Rig

    @property
    def person(self) -> Int[Array, "F M S"]:
        """Person id of every detection (real or double), -1 for clutter and padding."""
        J = len(SKELETON_JOINTS)
        return jnp.where(self.frames.instance >= 0, self.frames.instance // J, -1)


def skeleton_motion(
    key: PRNGKeyArray,
    num_people: Int[Array, ""],
    *,
    max_people: int,
    num_frames: int,
    fps: float,
    dtype,
) -> tuple[Float[Array, "F K J 3"], Bool[Array, " K"]]:
    """Joints ``(F, K, 17, 3)`` (metres) of ``K = max_people`` walking people, frames
    ``1 / fps`` s apart, and which people exist ``(K,)`` (the first ``num_people``).

    Each person: scale in :data:`HEIGHT_SCALE`, speed 0.3–1 m/s, heading turning at up to
    0.6 rad/s, limbs swinging ±10–25° at 0.7–1 Hz; starts in a distinct cell of a 3 × 3
    grid of 1 m cells around the origin (so people start ≥ 0.6 m apart).
    """
    K, F = max_people, num_frames
    ks = jax.random.split(key, 8)
    u = lambda k, lo, hi: lo + (hi - lo) * jax.random.uniform(k, (K,), dtype=dtype)  # noqa: E731
    scale = u(ks[0], *HEIGHT_SCALE)
    speed = u(ks[1], *_SPEED)
    turn = u(ks[2], -_TURN, _TURN)
    heading0 = u(ks[3], 0.0, 2.0 * math.pi)
    swing = jnp.deg2rad(u(ks[4], *_SWING_DEG))
    step_hz = u(ks[5], *_STEP_HZ)
    phase = u(ks[6], 0.0, 2.0 * math.pi)
    cell = jax.random.permutation(ks[7], 9)[:K]  # K <= 9 distinct cells
    jitter = _GRID_JITTER * (
        2.0 * jax.random.uniform(jax.random.fold_in(key, 8), (K, 2), dtype=dtype) - 1.0
    )
    start = (
        _GRID_SPACING * jnp.stack([cell % 3 - 1, cell // 3 - 1], axis=-1).astype(dtype) + jitter
    )  # (K, 2)

    t = jnp.arange(F, dtype=dtype) / fps  # (F,)
    heading = heading0[None, :] + turn[None, :] * t[:, None]  # (F, K)
    step = (speed / fps)[None, :, None] * jnp.stack(
        [jnp.cos(heading), jnp.sin(heading)], axis=-1
    )  # (F, K, 2)
    position = start[None] + jnp.cumsum(step, axis=0) - step[:1]  # the walk starts at `start`

    theta = swing[None, :] * jnp.sin(
        2.0 * math.pi * step_hz[None, :] * t[:, None] + phase[None, :]
    )  # (F, K)
    body = scale[:, None, None] * jnp.asarray(SKELETON_TEMPLATE, dtype)[None]  # (K, J, 3)
    pivot = body[:, _SWING_PIVOT]  # (K, J, 3)
    angle = theta[..., None] * jnp.asarray(_SWING_SIGN, dtype)[None, None, :]  # (F, K, J)
    d = (body - pivot)[None]  # (1, K, J, 3)
    c, s = jnp.cos(angle), jnp.sin(angle)
    swung = pivot[None] + jnp.stack(
        [
            c * d[..., 0] + s * d[..., 2],
            jnp.broadcast_to(d[..., 1], c.shape),
            -s * d[..., 0] + c * d[..., 2],
        ],
        axis=-1,
    )  # (F, K, J, 3)
    ch, sh = jnp.cos(heading)[..., None], jnp.sin(heading)[..., None]  # (F, K, 1)
    world = jnp.stack(
        [
            ch * swung[..., 0] - sh * swung[..., 1] + position[..., 0:1],
            sh * swung[..., 0] + ch * swung[..., 1] + position[..., 1:2],
            swung[..., 2],
        ],
        axis=-1,
    )
    exists = jnp.arange(K) < num_people
    return world, exists


def generate_skeleton_scenes(
    key: PRNGKeyArray,
    rig: Rig,
    num_people: Int[ArrayLike, ""],
    sigma_px: Real[ArrayLike, ""],
    *,
    realism: Realism = Realism(),
    keypoint_errors: KeypointErrors = KeypointErrors(),
    num_frames: int,
    max_people: int = 5,
    fps: float = 10.0,
    image_size: tuple[int, int] = RING_IMAGE_SIZE,
    double_capacity: int = 0,
    clutter_capacity: int = 0,
) -> SkeletonScenes:
    """``num_frames`` frames of ``num_people`` walking people (:func:`skeleton_motion`) seen by
    ``rig`` (e.g. :func:`ring_rig`; ``K (M, 3, 3)``), every joint type a class: detections
    ``frames.xy (F, M, S, 2)`` with ``S = 17 · max_people + double_capacity + clutter_capacity``.

    The calibration error (:func:`perturb_rig`) and the views' noise levels
    (:func:`view_sigmas`) are drawn once for the sequence, as a real rig's would be; each
    frame is then rendered with :func:`render_points` (clutter of a uniform joint class).
    ``num_people`` (``<= max_people <= 9``), ``sigma_px`` and the ``realism`` fields may be
    traced, and so may ``keypoint_errors`` (:class:`KeypointErrors`: joints missed, more
    often where another person hides them, and left/right swaps, drawn per frame); the other
    keyword arguments are static. For :func:`cdog_jax.associate_classes` pass
    ``frames.xy, frames.mask, frames.class_id`` with ``class_names=SKELETON_JOINTS``.
    """
    expect_args(
        "generate_skeleton_scenes",
        key=(key, ARRAY),
        rig=(rig, Rig),
        realism=(realism, Realism),
        keypoint_errors=(keypoint_errors, KeypointErrors),
    )
    for name, value, low in (
        ("num_frames", num_frames, 1),
        ("max_people", max_people, 1),
        ("double_capacity", double_capacity, 0),
        ("clutter_capacity", clutter_capacity, 0),
    ):
        if not isinstance(value, int) or value < low:
            raise ValueError(f"{name} must be a Python int >= {low}; got {value!r}")
    if max_people > 9:
        raise ValueError(f"max_people must be <= 9 (distinct start cells); got {max_people}")
    if isinstance(num_people, int) and not 0 <= num_people <= max_people:
        raise ValueError(f"num_people must be in [0, max_people={max_people}]; got {num_people}")
    if not fps > 0:
        raise ValueError(f"fps must be > 0; got {fps!r}")
    dtype = rig.K.dtype
    return _skeleton_scenes(
        key,
        rig,
        jnp.asarray(num_people, jnp.int32),
        jnp.asarray(sigma_px, dtype),
        realism.as_arrays(dtype),
        keypoint_errors.as_arrays(dtype),
        num_frames=num_frames,
        max_people=max_people,
        fps=float(fps),
        image_size=tuple(image_size),
        double_capacity=double_capacity,
        clutter_capacity=clutter_capacity,
    )


@functools.partial(
    jax.jit,
    static_argnames=(
        "num_frames",
        "max_people",
        "fps",
        "image_size",
        "double_capacity",
        "clutter_capacity",
    ),
)
def _skeleton_scenes(
    key,
    rig,
    num_people,
    sigma_px,
    realism,
    keypoint_errors,
    *,
    num_frames,
    max_people,
    fps,
    image_size,
    double_capacity,
    clutter_capacity,
):
    dtype = rig.K.dtype
    J = len(SKELETON_JOINTS)
    k_motion, k_rig, k_sigma, k_render = jax.random.split(key, 4)
    joints, exists = skeleton_motion(
        k_motion, num_people, max_people=max_people, num_frames=num_frames, fps=fps, dtype=dtype
    )
    true_rig = perturb_rig(k_rig, rig, realism)
    sigma_view = view_sigmas(k_sigma, sigma_px, realism, rig.num_views)
    point_exists = jnp.repeat(exists, J)  # (K·J,) point id = person · J + joint
    point_class = jnp.tile(jnp.arange(J, dtype=jnp.int32), max_people)

    def frame(k, X):
        scene = render_points(
            k,
            true_rig,
            X.reshape(-1, 3),
            point_exists,
            point_class,
            sigma_view,
            realism,
            image_size=image_size,
            double_capacity=double_capacity,
            clutter_capacity=clutter_capacity,
            num_classes=J,
        )
        hidden = hidden_joints(true_rig, X, exists, image_size)  # (K, J, M)
        return detector_errors(k, scene, hidden.reshape(-1, rig.num_views), keypoint_errors)

    frames = jax.vmap(frame)(jax.random.split(k_render, num_frames), joints)
    return SkeletonScenes(frames=frames, joints3d=joints, exists=exists, rig=true_rig)
