"""Benchmark scenes (SPEC §3): uniform 3D points seen by ≥ 2 views, noisy shuffled detections."""

import functools
from collections.abc import Sequence
from typing import Union

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import ArrayLike, PRNGKeyArray, Real

from .._types import Array, Bool, Float, Int
from ..geometry._camera import Rig
from ..geometry._projection import project
from ._rig import DEFAULT_BOX, IMAGE_SIZE


class Scene(eqx.Module):
    """One synthetic scene with ground truth (a batch adds a leading ``B`` to every field).

    Attributes:
        xy: ``(M, P, 2)`` noisy detections (pixels); padded slots hold 0.
        mask: ``(M, P)`` bool, slot holds a detection.
        instance: ``(M, P)`` int32 ground-truth point id of each detection, -1 for padding
            (and clutter, when the generator adds it).
        points3d: ``(P, 3)`` ground-truth world point of each instance id (scene units);
            rows ``>= num_points`` are 0.
        num_points: ``()`` int32 number of instances (ids ``0 … num_points-1``).
    """

    xy: Float[Array, "M P 2"]
    mask: Bool[Array, "M P"]
    instance: Int[Array, "M P"]
    points3d: Float[Array, "P 3"]
    num_points: Int[Array, ""]


# A corner of the sampling box: a (3,) sequence of floats or an array.
_Corner = Union[Sequence[float], Real[ArrayLike, " 3"]]


def generate_scene(
    key: PRNGKeyArray,
    rig: Rig,
    num_points: Int[ArrayLike, ""],
    sigma_px: Real[ArrayLike, ""],
    *,
    capacity: int,
    box: tuple[_Corner, _Corner] | Real[ArrayLike, "2 3"] = DEFAULT_BOX,
    image_size: tuple[int, int] = IMAGE_SIZE,
    oversample: int = 4,
) -> Scene:
    """One benchmark scene (SPEC §3): uniform points seen by ≥ 2 views, noisy, shuffled.

    ``capacity * oversample`` candidates are drawn uniformly in ``box``; a candidate is
    visible in view ``m`` when it is in front of the camera and its noise-free pixel lies in
    ``[0, w) × [0, h)``. The first ``num_points`` candidates visible in ≥ 2 views become
    instances ``0 … n-1`` (fewer if too few candidates qualify: ``Scene.num_points`` holds
    the actual count). N(0, σ²) noise is added to x and y independently (a noisy detection
    may fall slightly outside the image), then the ``P`` slots of every view are permuted
    independently, so slot order and padding position carry no information.

    Args:
        key: PRNG key.
        rig: ``M`` cameras (its dtype is the scene's dtype).
        num_points: ``()`` int, requested instance count; may be traced (then clipped to
            ``[0, capacity]``; a Python int outside that range raises ``ValueError``).
        sigma_px: ``()`` pixel noise std σ; may be traced.
        capacity: static slot count ``P`` per view (≥ 1).
        box: lower and upper ``(3,)`` corners of the sampling box (scene units), or a
            ``(2, 3)`` array; may be traced.
        image_size: static ``(width, height)`` in pixels.
        oversample: static; candidates drawn per slot.

    Returns:
        A :class:`Scene` with ``xy (M, P, 2)``, ``mask (M, P)``, ``instance (M, P)``
        (-1 and xy 0 in padded slots), ``points3d (P, 3)`` and ``num_points``.

    Jitted inside (``capacity``, ``image_size``, ``oversample`` static), so eager calls
    compile once per shape; it also works under an outer ``jit`` or ``vmap``. For a batch
    see :func:`generate_scenes`.
    """
    _check_static(capacity, image_size, oversample)
    if isinstance(num_points, int) and not 0 <= num_points <= capacity:
        raise ValueError(f"num_points must be in [0, capacity={capacity}]; got {num_points}")
    dtype = rig.K.dtype
    return _generate_scene(
        key,
        rig,
        jnp.asarray(num_points, dtype=jnp.int32),
        jnp.asarray(sigma_px, dtype=dtype),
        _box_array(box, dtype),
        capacity=capacity,
        image_size=tuple(image_size),
        oversample=oversample,
    )


def generate_scenes(
    key: PRNGKeyArray,
    rig: Rig,
    num_points: Int[ArrayLike, " B"],
    sigma_px: Real[ArrayLike, " B"],
    *,
    capacity: int,
    box: tuple[_Corner, _Corner] | Real[ArrayLike, "2 3"] = DEFAULT_BOX,
    image_size: tuple[int, int] = IMAGE_SIZE,
    oversample: int = 4,
) -> Scene:
    """A batch of ``B`` scenes, one per entry of ``num_points`` and ``sigma_px`` (both
    ``(B,)``, may be traced), sharing ``rig`` and ``box``: :func:`generate_scene` vmapped
    over ``jax.random.split(key, B)``.

    Returns a :class:`Scene` whose fields have a leading ``B`` axis. Counts and noise
    levels are traced, so a whole benchmark grid compiles once per ``(B, capacity)``.
    """
    _check_static(capacity, image_size, oversample)
    dtype = rig.K.dtype
    num_points = jnp.asarray(num_points, dtype=jnp.int32)
    sigma_px = jnp.asarray(sigma_px, dtype=dtype)
    if num_points.ndim != 1 or sigma_px.shape != num_points.shape:
        raise ValueError(
            f"num_points and sigma_px must both have shape (B,); got {num_points.shape} and {sigma_px.shape}"
        )
    keys = jax.random.split(key, num_points.shape[0])
    one = functools.partial(_generate_scene, capacity=capacity, image_size=tuple(image_size), oversample=oversample)
    return jax.vmap(one, in_axes=(0, None, 0, 0, None))(keys, rig, num_points, sigma_px, _box_array(box, dtype))


def _check_static(capacity, image_size, oversample) -> None:
    if not isinstance(capacity, int) or capacity < 1:
        raise ValueError(f"capacity must be a Python int >= 1; got {capacity!r}")
    if not isinstance(oversample, int) or oversample < 1:
        raise ValueError(f"oversample must be a Python int >= 1; got {oversample!r}")
    if len(image_size) != 2:
        raise ValueError(f"image_size must be (width, height); got {image_size!r}")


def _box_array(box, dtype) -> Float[Array, "2 3"]:
    lo, hi = (jnp.asarray(corner, dtype=dtype) for corner in box)
    if lo.shape != (3,) or hi.shape != (3,):
        raise ValueError(f"box must be two (3,) corners; got shapes {lo.shape} and {hi.shape}")
    return jnp.stack([lo, hi])


@functools.partial(jax.jit, static_argnames=("capacity", "image_size", "oversample"))
def _generate_scene(
    key: PRNGKeyArray,
    rig: Rig,
    num_points: Int[Array, ""],
    sigma_px: Float[Array, ""],
    box: Float[Array, "2 3"],
    *,
    capacity: int,
    image_size: tuple[int, int],
    oversample: int,
) -> Scene:
    """Kernel of :func:`generate_scene` on canonical arguments (int32 count, rig-dtype σ
    and ``box (2, 3)``), so that equal shapes share one compilation."""
    dtype = rig.K.dtype
    M, P, Q = rig.num_views, capacity, capacity * oversample
    k_points, k_noise, k_perm = jax.random.split(key, 3)
    num_points = jnp.clip(num_points, 0, P)

    # Candidates and their visibility, decided on the noise-free projection.
    u = jax.random.uniform(k_points, (Q, 3), dtype=dtype)
    X_cand = box[0][None] + u * (box[1] - box[0])[None]  # (Q, 3)
    # Per point: camera_points adds t with implicit rank broadcasting for batched points.
    xy_cand, front = jax.vmap(project, in_axes=(None, 0))(rig, X_cand)  # (Q, M, 2), (Q, M)
    w, h = image_size
    x, y = xy_cand[..., 0], xy_cand[..., 1]
    vis_cand = front & (x >= 0) & (x < w) & (y >= 0) & (y < h)  # (Q, M)

    # Keep the first num_points candidates seen twice; their rank is their instance id.
    good = jnp.sum(vis_cand, axis=-1, dtype=jnp.int32) >= 2
    rank = jnp.cumsum(good, dtype=jnp.int32) - 1
    keep = good & (rank < num_points)
    dest = jnp.where(keep, rank, P)  # out of range → dropped by the scatter
    points3d = jnp.zeros((P, 3), dtype).at[dest].set(X_cand, mode="drop")
    xy_inst = jnp.zeros((P, M, 2), dtype).at[dest].set(xy_cand, mode="drop")
    vis_inst = jnp.zeros((P, M), bool).at[dest].set(vis_cand, mode="drop")
    n_kept = jnp.sum(keep, dtype=jnp.int32)

    xy_inst = xy_inst + sigma_px * jax.random.normal(k_noise, (P, M, 2), dtype=dtype)

    # Slot s of view m holds instance order[m, s]: an independent uniform permutation per
    # view, the argsort of random 32-bit keys (one sort; ties, p ≈ P²/2³³, keep id order).
    order = jnp.argsort(jax.random.bits(k_perm, (M, P), dtype=jnp.uint32), axis=-1)  # (M, P)
    order = order.astype(jnp.int32)
    view = jnp.arange(M, dtype=jnp.int32)[:, None]  # (M, 1): index broadcast against (M, P)
    mask = vis_inst[order, view]  # (M, P)
    xy = jnp.where(mask[..., None], xy_inst[order, view], 0.0)  # (M, P, 2)
    instance = jnp.where(mask, order, -1)
    return Scene(xy=xy, mask=mask, instance=instance, points3d=points3d, num_points=n_kept)
