"""Detections of known 3D points as a real detector gives them (docs/BENCHMARK.md §7): heavy-tailed
per-view noise, doubles and clutter, in shuffled padded slots with the ground truth.

:func:`render_points` is the kernel shared by the box scenes (:func:`generate_realistic_scene`)
and the skeleton scenes (:mod:`._skeleton`).
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import ArrayLike, PRNGKeyArray, Real

from .._expect import ARRAY, expect_args
from .._types import Array, Bool, Float, Int
from ..geometry._camera import Rig
from ..geometry._projection import project_views_last
from ._realism import Realism, perturb_rig, unit_noise, view_sigmas
from ._rig import DEFAULT_BOX, IMAGE_SIZE
from ._scene import Scene, _box_array, _check_static, _clipped_poisson, _generate_scene

REAL, DOUBLE, CLUTTER = 0, 1, 2
"""Values of :attr:`RealScene.kind` (``-1``: padding)."""


class RealScene(eqx.Module):
    """One realistic scene with ground truth (a batch adds leading axes to every field).

    Attributes:
        xy: ``(M, S, 2)`` detections (pixels); padded slots hold 0.
        mask: ``(M, S)`` bool, slot holds a detection.
        instance: ``(M, S)`` int32 point id of a real detection or a double, -1 for clutter
            and padding.
        kind: ``(M, S)`` int32 ``REAL`` (0), ``DOUBLE`` (1), ``CLUTTER`` (2), -1 padding.
        class_id: ``(M, S)`` int32 class of the detection (the point's; clutter: uniform), 0 in padding.
        points3d: ``(I, 3)`` ground-truth world points (scene units), by point id.
        num_points: ``()`` int32 points that exist (ids below it; the others are padding).
        sigma_view: ``(M,)`` noise scale of every view (pixels).
        rig: the true cameras the detections were rendered with (the nominal rig plus the
            pose errors; the method is given the nominal one).
        num_doubles, num_clutter: ``(M,)`` int32 doubles and clutter per view.
    """

    xy: Float[Array, "M S 2"]
    mask: Bool[Array, "M S"]
    instance: Int[Array, "M S"]
    kind: Int[Array, "M S"]
    class_id: Int[Array, "M S"]
    points3d: Float[Array, "I 3"]
    num_points: Int[Array, ""]
    sigma_view: Float[Array, " M"]
    rig: Rig
    num_doubles: Int[Array, " M"]
    num_clutter: Int[Array, " M"]

    def as_scene(self) -> Scene:
        """The benchmark :class:`Scene` for :func:`cdog_jax.metrics.scene_metrics`: doubles
        count as false detections there (instance -1), as clutter does. ``points3d`` is
        padded with rows of 0 to ``S`` rows, one per possible instance id."""
        I, S = self.points3d.shape[-2], self.xy.shape[-2]
        pad = [(0, 0)] * (self.points3d.ndim - 2) + [(0, max(S - I, 0)), (0, 0)]
        return Scene(
            xy=self.xy,
            mask=self.mask,
            instance=jnp.where(self.kind == REAL, self.instance, -1),
            points3d=jnp.pad(self.points3d, pad),
            num_points=self.num_points,
            num_clutter=self.num_clutter + self.num_doubles,
        )


# fold_in tags, one per source of randomness.
_NOISE, _DOUBLE_PICK, _DOUBLE_XY, _CLUTTER_COUNT, _CLUTTER_XY, _CLUTTER_CLASS, _PERM = range(7)


def render_points(
    key: PRNGKeyArray,
    rig: Rig,
    X: Float[Array, "I 3"],
    exists: Bool[Array, " I"],
    point_class: Int[Array, " I"],
    sigma_view: Float[Array, " M"],
    realism: Realism,
    *,
    image_size: tuple[int, int],
    double_capacity: int,
    clutter_capacity: int,
    num_classes: int = 1,
) -> RealScene:
    """Detections of points ``X`` seen by the cameras ``rig`` (the *true* ones), one scene.

    A point is detected in view ``m`` when it exists, is in front of the camera and its
    noise-free pixel is inside ``[0, w) × [0, h)``; the detection is that pixel plus
    ``sigma_view[m] ·`` :func:`unit_noise`. Each detection gets a double with probability
    ``realism.double_rate`` (at the detection plus ``N(0, double_offset_px²)`` per
    coordinate; the first ``double_capacity`` per view are kept), and each view
    ``min(Poisson(clutter_rate), clutter_capacity)`` clutter detections uniform in the
    image, of a uniform class. The ``S = I + double_capacity + clutter_capacity`` slots of
    every view are shuffled independently. Pure JAX: works under ``jit`` and ``vmap``.

    Returns a :class:`RealScene` (``rig`` is the one given, the true rig).
    """
    dtype = rig.K.dtype
    M, I, D, C = rig.num_views, X.shape[0], double_capacity, clutter_capacity
    tag = lambda t: jax.random.fold_in(key, t)  # noqa: E731

    xy_true, front = project_views_last(rig, X)  # (I, M, 2), (I, M)
    w, h = image_size
    x, y = xy_true[..., 0], xy_true[..., 1]
    seen = exists[:, None] & front & (x >= 0) & (x < w) & (y >= 0) & (y < h)  # (I, M)
    xy_real = xy_true + sigma_view[None, :, None] * unit_noise(tag(_NOISE), (I, M), realism, dtype)

    # Doubles: the first D doubled detections of each view (in point order) get a row.
    doubled = seen & (
        jax.random.uniform(tag(_DOUBLE_PICK), (I, M), dtype=dtype) < realism.double_rate
    )
    rank = jnp.cumsum(doubled, axis=0, dtype=jnp.int32) - 1  # (I, M)
    row = jnp.where(doubled & (rank < D), rank, D)  # D: dropped by the scatter
    views = jnp.broadcast_to(jnp.arange(M, dtype=jnp.int32)[None, :], (I, M))
    offset = realism.double_offset_px * jax.random.normal(tag(_DOUBLE_XY), (I, M, 2), dtype=dtype)
    xy_double = jnp.zeros((D, M, 2), dtype).at[row, views].set(xy_real + offset, mode="drop")
    id_double = (
        jnp.full((D, M), -1, jnp.int32)
        .at[row, views]
        .set(jnp.broadcast_to(jnp.arange(I, dtype=jnp.int32)[:, None], (I, M)), mode="drop")
    )
    has_double = id_double >= 0  # (D, M)
    num_doubles = jnp.sum(has_double, axis=0, dtype=jnp.int32)

    num_clutter = _clipped_poisson(
        tag(_CLUTTER_COUNT), jnp.asarray(realism.clutter_rate, dtype), C, M
    )  # (M,)
    w_h = jnp.asarray(image_size, dtype=dtype)
    xy_clutter = jax.random.uniform(tag(_CLUTTER_XY), (C, M, 2), dtype=dtype) * w_h[None, None, :]
    has_clutter = jnp.arange(C, dtype=jnp.int32)[:, None] < num_clutter[None, :]  # (C, M)
    class_clutter = jax.random.randint(tag(_CLUTTER_CLASS), (C, M), 0, num_classes, dtype=jnp.int32)

    safe_id = jnp.maximum(id_double, 0)
    vis_src = jnp.concatenate([seen, has_double, has_clutter])  # (S, M)
    xy_src = jnp.concatenate([xy_real, xy_double, xy_clutter])  # (S, M, 2)
    id_src = jnp.concatenate(
        [
            jnp.broadcast_to(jnp.arange(I, dtype=jnp.int32)[:, None], (I, M)),
            id_double,
            jnp.full((C, M), -1, jnp.int32),
        ]
    )
    kind_src = jnp.concatenate(
        [
            jnp.full((I, M), REAL, jnp.int32),
            jnp.full((D, M), DOUBLE, jnp.int32),
            jnp.full((C, M), CLUTTER, jnp.int32),
        ]
    )
    class_src = jnp.concatenate(
        [jnp.broadcast_to(point_class[:, None], (I, M)), point_class[safe_id], class_clutter]
    )

    # An independent uniform permutation of the S rows of every view.
    S = I + D + C
    order = jnp.argsort(jax.random.bits(tag(_PERM), (M, S), dtype=jnp.uint32), axis=-1).astype(
        jnp.int32
    )
    view = jnp.arange(M, dtype=jnp.int32)[:, None]
    mask = vis_src[order, view]  # (M, S)
    return RealScene(
        xy=jnp.where(mask[..., None], xy_src[order, view], 0.0),
        mask=mask,
        instance=jnp.where(mask, id_src[order, view], -1),
        kind=jnp.where(mask, kind_src[order, view], -1),
        class_id=jnp.where(mask, class_src[order, view], 0).astype(jnp.int32),
        points3d=X,
        num_points=jnp.sum(exists, dtype=jnp.int32),
        sigma_view=sigma_view,
        rig=rig,
        num_doubles=num_doubles,
        num_clutter=num_clutter,
    )


def generate_realistic_scene(
    key: PRNGKeyArray,
    rig: Rig,
    num_points: Int[ArrayLike, ""],
    sigma_px: Real[ArrayLike, ""],
    *,
    realism: Realism = Realism(),
    capacity: int,
    box=DEFAULT_BOX,
    image_size: tuple[int, int] = IMAGE_SIZE,
    double_capacity: int = 0,
    clutter_capacity: int = 0,
) -> RealScene:
    """A benchmark box scene (the points of :func:`generate_scene`: uniform in ``box (2, 3)``,
    seen by ≥ 2 views of the nominal ``rig``, ``K (M, 3, 3)``) rendered with the
    :class:`Realism` options.

    Per scene: the true rig is ``rig`` with pose errors (:func:`perturb_rig`), the views'
    noise levels are :func:`view_sigmas` of ``sigma_px``; then :func:`render_points`.
    ``num_points``, ``sigma_px`` and every field of ``realism`` may be traced (a sweep over
    them compiles once); ``capacity``, ``image_size``, ``double_capacity`` and
    ``clutter_capacity`` are static. Returns a :class:`RealScene` with
    ``S = capacity + double_capacity + clutter_capacity`` slots per view.
    """
    expect_args(
        "generate_realistic_scene", key=(key, ARRAY), rig=(rig, Rig), realism=(realism, Realism)
    )
    _check_static(capacity, image_size, 1, clutter_capacity)
    if not isinstance(double_capacity, int) or double_capacity < 0:
        raise ValueError(f"double_capacity must be a Python int >= 0; got {double_capacity!r}")
    dtype = rig.K.dtype
    return _realistic_scene(
        key,
        rig,
        jnp.asarray(num_points, jnp.int32),
        jnp.asarray(sigma_px, dtype),
        realism.as_arrays(dtype),
        _box_array(box, dtype),
        capacity=capacity,
        image_size=tuple(image_size),
        double_capacity=double_capacity,
        clutter_capacity=clutter_capacity,
    )


@functools.partial(
    jax.jit, static_argnames=("capacity", "image_size", "double_capacity", "clutter_capacity")
)
def _realistic_scene(
    key,
    rig,
    num_points,
    sigma_px,
    realism,
    box,
    *,
    capacity,
    image_size,
    double_capacity,
    clutter_capacity,
):
    k_points, k_rig, k_sigma, k_render = jax.random.split(key, 4)
    zero = jnp.zeros((), sigma_px.dtype)
    points = _generate_scene(
        k_points,
        rig,
        num_points,
        zero,
        box,
        zero,
        zero,
        capacity=capacity,
        image_size=image_size,
        oversample=4,
        clutter_capacity=0,
    )
    exists = jnp.arange(capacity, dtype=jnp.int32) < points.num_points
    true_rig = perturb_rig(k_rig, rig, realism)
    sigma_view = view_sigmas(k_sigma, sigma_px, realism, rig.num_views)
    return render_points(
        k_render,
        true_rig,
        points.points3d,
        exists,
        jnp.zeros((capacity,), jnp.int32),
        sigma_view,
        realism,
        image_size=image_size,
        double_capacity=double_capacity,
        clutter_capacity=clutter_capacity,
    )
