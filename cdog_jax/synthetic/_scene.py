"""Benchmark scenes (docs/BENCHMARK.md §1): uniform 3D points seen by ≥ 2 views, noisy shuffled detections."""

import functools
from collections.abc import Sequence
from typing import Union

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import ArrayLike, PRNGKeyArray, Real

from .._expect import ARRAY, expect_args
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
            and for clutter (a valid slot with id -1 is a false positive).
        points3d: ``(P, 3)`` ground-truth world point of each instance id (scene units);
            rows ``>= num_points`` are 0.
        num_points: ``()`` int32 number of instances (ids ``0 … num_points-1``). With
            ``drop_rate > 0`` an instance may have fewer than 2 (even 0) detections left.
        num_clutter: ``(M,)`` int32 clutter detections per view (after clipping to
            ``clutter_capacity``), or None for a scene built by hand.
    """

    xy: Float[Array, "M P 2"]
    mask: Bool[Array, "M P"]
    instance: Int[Array, "M P"]
    points3d: Float[Array, "P 3"]
    num_points: Int[Array, ""]
    num_clutter: Int[Array, " M"] | None = None


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
    drop_rate: Real[ArrayLike, ""] = 0.0,
    clutter_rate: Real[ArrayLike, ""] = 0.0,
    clutter_capacity: int = 0,
) -> Scene:
    """One benchmark scene (docs/BENCHMARK.md §1): uniform points seen by ≥ 2 views, noisy, shuffled.

    ``capacity * oversample`` candidates are drawn uniformly in ``box``; a candidate is
    visible in view ``m`` when it is in front of the camera and its noise-free pixel lies in
    ``[0, w) × [0, h)``. The first ``num_points`` candidates visible in ≥ 2 views become
    instances ``0 … n-1`` (fewer if too few candidates qualify: ``Scene.num_points`` holds
    the actual count). N(0, σ²) noise is added to x and y independently (a noisy detection
    may fall slightly outside the image), then the ``P`` slots of every view are permuted
    independently, so slot order and padding position carry no information.

    Beyond the paper (docs/BENCHMARK.md §1; both off by default, and then the scene is identical, bit for
    bit, to one generated without these arguments):

    - *Missed detections*: each visible detection is dropped independently with probability
      ``drop_rate``. Which points are kept (visible in ≥ 2 views) is decided on the true
      visibility, *before* the drops, so the point set does not depend on the drop rate;
      an instance may therefore end with fewer than 2 detections (then it is no
      ground-truth group for the metrics, docs/BENCHMARK.md §2) or none at all.
    - *Clutter*: view ``m`` gets ``min(Poisson(clutter_rate), clutter_capacity)`` false
      detections (the clipped Poisson is drawn directly, by inversion) uniform in ``[0, w) × [0, h)`` with instance id -1, in ``clutter_capacity``
      extra slots per view that are shuffled together with the real ones. The clipped count
      is returned in ``Scene.num_clutter``; choose ``clutter_capacity`` well above the rate
      (e.g. rate + 4·√rate + 4) so that clipping is rare, and check the mean count.

    The new randomness comes from ``jax.random.fold_in`` keys, so the points, noise and (at
    ``clutter_capacity = 0``) the permutation are the same as without drops and clutter.

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
        drop_rate: ``()`` probability in [0, 1] that a visible detection is missed; may be
            traced.
        clutter_rate: ``()`` mean clutter detections per view (≥ 0); may be traced.
        clutter_capacity: static clutter slots per view (≥ 0).

    Returns:
        A :class:`Scene` with ``P = capacity + clutter_capacity`` slots: ``xy (M, P, 2)``,
        ``mask (M, P)``, ``instance (M, P)`` (-1 and xy 0 in padded slots, -1 for clutter),
        ``points3d (P, 3)``, ``num_points`` and ``num_clutter (M,)``.

    Jitted inside (``capacity``, ``image_size``, ``oversample``, ``clutter_capacity``
    static; the rates are traced, so a sweep over them compiles once), so eager calls
    compile once per shape; it also works under an outer ``jit`` or ``vmap``. For a batch
    see :func:`generate_scenes`.
    """
    expect_args(
        "generate_scene",
        key=(key, ARRAY),
        rig=(rig, Rig),
        num_points=(num_points, ARRAY),
        sigma_px=(sigma_px, ARRAY),
    )
    _check_static(capacity, image_size, oversample, clutter_capacity)
    if isinstance(num_points, int) and not 0 <= num_points <= capacity:
        raise ValueError(f"num_points must be in [0, capacity={capacity}]; got {num_points}")
    _check_rates(drop_rate, clutter_rate)
    dtype = rig.K.dtype
    return _generate_scene(
        key,
        rig,
        jnp.asarray(num_points, dtype=jnp.int32),
        jnp.asarray(sigma_px, dtype=dtype),
        _box_array(box, dtype),
        jnp.asarray(drop_rate, dtype=dtype),
        jnp.asarray(clutter_rate, dtype=dtype),
        capacity=capacity,
        image_size=tuple(image_size),
        oversample=oversample,
        clutter_capacity=clutter_capacity,
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
    drop_rate: Real[ArrayLike, "*B"] = 0.0,
    clutter_rate: Real[ArrayLike, "*B"] = 0.0,
    clutter_capacity: int = 0,
) -> Scene:
    """A batch of ``B`` scenes, one per entry of ``num_points`` and ``sigma_px`` (both
    ``(B,)``, may be traced), sharing ``rig`` and ``box``: :func:`generate_scene` vmapped
    over ``jax.random.split(key, B)``. ``drop_rate`` and ``clutter_rate`` are scalars or
    ``(B,)`` (may be traced); ``clutter_capacity`` is static.

    Returns a :class:`Scene` whose fields have a leading ``B`` axis. Counts, noise levels
    and rates are traced, so a whole benchmark grid compiles once per ``(B, capacity)``.
    """
    expect_args(
        "generate_scenes",
        key=(key, ARRAY),
        rig=(rig, Rig),
        num_points=(num_points, ARRAY),
        sigma_px=(sigma_px, ARRAY),
    )
    _check_static(capacity, image_size, oversample, clutter_capacity)
    _check_rates(drop_rate, clutter_rate)
    dtype = rig.K.dtype
    num_points = jnp.asarray(num_points, dtype=jnp.int32)
    sigma_px = jnp.asarray(sigma_px, dtype=dtype)
    if num_points.ndim != 1 or sigma_px.shape != num_points.shape:
        raise ValueError(
            f"num_points and sigma_px must both have shape (B,); got {num_points.shape} and {sigma_px.shape}"
        )
    B = num_points.shape[0]
    rates = []
    for name, rate in (("drop_rate", drop_rate), ("clutter_rate", clutter_rate)):
        rate = jnp.asarray(rate, dtype=dtype)
        if rate.shape not in ((), (B,)):
            raise ValueError(
                f"{name} must be a scalar or have shape (B,) = ({B},); got {rate.shape}"
            )
        rates.append(jnp.broadcast_to(rate, (B,)))
    keys = jax.random.split(key, B)
    one = functools.partial(
        _generate_scene,
        capacity=capacity,
        image_size=tuple(image_size),
        oversample=oversample,
        clutter_capacity=clutter_capacity,
    )
    return jax.vmap(one, in_axes=(0, None, 0, 0, None, 0, 0))(
        keys, rig, num_points, sigma_px, _box_array(box, dtype), *rates
    )


def _check_static(capacity, image_size, oversample, clutter_capacity=0) -> None:
    if not isinstance(capacity, int) or capacity < 1:
        raise ValueError(f"capacity must be a Python int >= 1; got {capacity!r}")
    if not isinstance(clutter_capacity, int) or clutter_capacity < 0:
        raise ValueError(f"clutter_capacity must be a Python int >= 0; got {clutter_capacity!r}")
    if not isinstance(oversample, int) or oversample < 1:
        raise ValueError(f"oversample must be a Python int >= 1; got {oversample!r}")
    if len(image_size) != 2:
        raise ValueError(f"image_size must be (width, height); got {image_size!r}")


def _check_rates(drop_rate, clutter_rate) -> None:
    """Range checks of rates given as Python numbers (traced rates cannot be checked)."""
    if isinstance(drop_rate, (int, float)) and not 0.0 <= drop_rate <= 1.0:
        raise ValueError(f"drop_rate must be in [0, 1]; got {drop_rate}")
    if isinstance(clutter_rate, (int, float)) and not clutter_rate >= 0.0:
        raise ValueError(f"clutter_rate must be >= 0; got {clutter_rate}")


def _box_array(box, dtype) -> Float[Array, "2 3"]:
    lo, hi = (jnp.asarray(corner, dtype=dtype) for corner in box)
    if lo.shape != (3,) or hi.shape != (3,):
        raise ValueError(f"box must be two (3,) corners; got shapes {lo.shape} and {hi.shape}")
    return jnp.stack([lo, hi])


def _clipped_poisson(
    key: PRNGKeyArray, rate: Float[Array, ""], cap: int, M: int
) -> Int[Array, " M"]:
    """``(M,)`` draws of ``min(Poisson(rate), cap)`` by inversion of the CDF on ``0 … cap``.

    Exact in distribution up to rounding of the CDF; much cheaper to compile than
    ``jax.random.poisson`` (whose rejection loops cost seconds under ``vmap``), and the
    clipping is part of the draw: ``count = #{k < cap : u ≥ F(k)}``, so ``u ≥ F(cap − 1)``,
    i.e. ``Poisson ≥ cap``, gives ``cap``.
    """
    dtype = rate.dtype
    k = jnp.arange(cap, dtype=dtype)  # (cap,)
    # log pmf, in log space so that exp(-rate) cannot underflow for large rates; at rate 0
    # all the mass is on k = 0 (log 0 guarded by the where).
    pos = rate > 0
    log_rate = jnp.log(jnp.where(pos, rate, 1.0))
    log_pmf = jnp.where(
        pos, k * log_rate - rate - jax.lax.lgamma(k + 1.0), jnp.where(k == 0, 0.0, -jnp.inf)
    )
    cdf = jnp.cumsum(jnp.exp(log_pmf))  # (cap,) F(0 … cap-1)
    u = jax.random.uniform(key, (M,), dtype=dtype)
    return jnp.sum(u[:, None] >= cdf[None, :], axis=1, dtype=jnp.int32)


# fold_in tags of the randomness added after the paper's generator (drops, clutter), so
# that the paper's split of the key (points, noise, permutation) stays as it was.
_DROP, _CLUTTER_COUNT, _CLUTTER_XY = 0x64726F70, 0x636E7400, 0x63787900


@functools.partial(
    jax.jit, static_argnames=("capacity", "image_size", "oversample", "clutter_capacity")
)
def _generate_scene(
    key: PRNGKeyArray,
    rig: Rig,
    num_points: Int[Array, ""],
    sigma_px: Float[Array, ""],
    box: Float[Array, "2 3"],
    drop_rate: Float[Array, ""],
    clutter_rate: Float[Array, ""],
    *,
    capacity: int,
    image_size: tuple[int, int],
    oversample: int,
    clutter_capacity: int,
) -> Scene:
    """Kernel of :func:`generate_scene` on canonical arguments (int32 count, rig-dtype σ,
    rates and ``box (2, 3)``), so that equal shapes share one compilation."""
    dtype = rig.K.dtype
    M, P, Q = rig.num_views, capacity, capacity * oversample
    C = clutter_capacity
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

    # Missed detections, after the ≥ 2-views selection (uniform < 0 never holds: rate 0
    # drops nothing and the rest of the scene does not depend on these draws).
    dropped = jax.random.uniform(jax.random.fold_in(key, _DROP), (P, M), dtype=dtype) < drop_rate
    vis_inst = vis_inst & ~dropped

    # Clutter in C extra rows per view (row P + j of view m is valid iff j < count[m]).
    num_clutter = _clipped_poisson(
        jax.random.fold_in(key, _CLUTTER_COUNT), clutter_rate, C, M
    )  # (M,)
    w_h = jnp.asarray(image_size, dtype=dtype)
    xy_clutter = (
        jax.random.uniform(jax.random.fold_in(key, _CLUTTER_XY), (C, M, 2), dtype=dtype)
        * w_h[None, None, :]
    )
    vis_src = jnp.concatenate(
        [vis_inst, jnp.arange(C, dtype=jnp.int32)[:, None] < num_clutter[None, :]]
    )  # (P + C, M)
    xy_src = jnp.concatenate([xy_inst, xy_clutter])  # (P + C, M, 2)
    id_src = jnp.concatenate(
        [jnp.arange(P, dtype=jnp.int32), jnp.full((C,), -1, jnp.int32)]
    )  # (P + C,)
    points3d = jnp.concatenate([points3d, jnp.zeros((C, 3), dtype)])

    # Slot s of view m holds row order[m, s]: an independent uniform permutation of the
    # P + C rows per view (real and clutter mixed), the argsort of random 32-bit keys (one
    # sort; ties, p ≈ P²/2³³, keep row order).
    order = jnp.argsort(
        jax.random.bits(k_perm, (M, P + C), dtype=jnp.uint32), axis=-1
    )  # (M, P + C)
    order = order.astype(jnp.int32)
    view = jnp.arange(M, dtype=jnp.int32)[:, None]  # (M, 1): index broadcast against (M, P + C)
    mask = vis_src[order, view]  # (M, P + C)
    xy = jnp.where(mask[..., None], xy_src[order, view], 0.0)  # (M, P + C, 2)
    instance = jnp.where(mask, id_src[order], -1)
    return Scene(
        xy=xy,
        mask=mask,
        instance=instance,
        points3d=points3d,
        num_points=n_kept,
        num_clutter=num_clutter,
    )
