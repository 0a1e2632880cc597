"""Eager checks at the API boundary: shapes, dtypes and values, before any work.

Messages say what was expected, what arrived and where (view and slot). Inside ``jit``
(traced inputs) value checks are impossible and skipped; shape checks always run.
"""

from __future__ import annotations

import numbers

import jax
import jax.numpy as jnp
import numpy as np

from .geometry._camera import Rig, cannot_change, check_rig_values


def _is_concrete(*arrays) -> bool:
    return not any(isinstance(a, jax.core.Tracer) for a in arrays)


# The JAX arrays (K, R, t) of the last rig whose values passed, and whether it was batched: a
# frame loop passes the same rig on every call, and reading its arrays back to the host and
# checking them cost about 0.2 ms a call. JAX arrays cannot change in place, so the same
# objects hold the same values; NumPy arrays can, and are checked every time.
_last_checked: tuple = ()


def check_rig(rig: Rig, batched: bool = False) -> None:
    """Shapes of a (possibly per-scene batched) rig, and its values when concrete."""
    global _last_checked
    arrays = (rig.K, rig.R, rig.t)
    if (
        len(_last_checked) == 4
        and _last_checked[3] == batched
        and all(a is b for a, b in zip(arrays, _last_checked))
    ):
        return
    lead = 1 if batched else 0
    K_shape = tuple(rig.K.shape)
    if len(K_shape) != 3 + lead or K_shape[-2:] != (3, 3):
        want = "(B, M, 3, 3)" if batched else "(M, 3, 3)"
        raise ValueError(f"rig.K must have shape {want}; got {K_shape}")
    M = K_shape[-3]
    if M < 2:
        raise ValueError(f"the rig must have at least 2 views; got {M}")
    if tuple(rig.R.shape) != K_shape:
        raise ValueError(f"rig.R must have shape {K_shape} like rig.K; got {tuple(rig.R.shape)}")
    if tuple(rig.t.shape) != K_shape[:-1]:
        raise ValueError(f"rig.t must have shape {K_shape[:-1]}; got {tuple(rig.t.shape)}")
    if _is_concrete(rig.K, rig.R, rig.t):
        K, R, t = (np.asarray(a, np.float64) for a in (rig.K, rig.R, rig.t))
        if not batched:
            check_rig_values(K, R, t)
        else:
            for b in range(K.shape[0]):
                try:
                    check_rig_values(K[b], R[b], t[b])
                except ValueError as e:
                    raise ValueError(f"rig of scene {b}: {e}") from None
        if cannot_change(*arrays):
            _last_checked = (*arrays, batched)


def check_observations(xy, mask, num_views: int, batched: bool = False) -> None:
    """``xy (…, M, P, 2)`` float and ``mask (…, M, P)`` bool; finite where valid."""
    lead = 1 if batched else 0
    xy_shape, mask_shape = tuple(np.shape(xy)), tuple(np.shape(mask))
    want_xy = "(B, M, P, 2)" if batched else "(M, P, 2)"
    if len(xy_shape) != 3 + lead or xy_shape[-1] != 2 or xy_shape[-3] != num_views:
        raise ValueError(
            f"xy must have shape {want_xy} with M={num_views} from the rig; got {xy_shape}"
        )
    if xy_shape[-2] < 1:
        raise ValueError(f"xy must have at least one slot per view (P >= 1); got {xy_shape}")
    if mask_shape != xy_shape[:-1]:
        raise ValueError(
            f"mask must have shape {xy_shape[:-1]} to match xy {xy_shape}; got {mask_shape}"
        )
    if np.dtype(getattr(mask, "dtype", np.asarray(mask).dtype)) != np.bool_:
        raise ValueError(f"mask must be boolean; got dtype {np.asarray(mask).dtype}")
    check_pixel_dtype(xy.dtype if hasattr(xy, "dtype") else np.asarray(xy).dtype, "xy")
    if _is_concrete(xy, mask):
        xy_h, mask_h = np.asarray(xy), np.asarray(mask)
        bad = mask_h & ~np.isfinite(xy_h).all(axis=-1)
        if bad.any():
            where = tuple(int(i) for i in np.argwhere(bad)[0])
            label = "scene {}, view {}, slot {}" if batched else "view {}, slot {}"
            raise ValueError(
                f"xy is not finite at {label.format(*where)} although mask is True there"
            )


def check_pixel_dtype(dtype, name: str) -> None:
    """Pixels are float32 or float64; integers are accepted (the caller converts them to the
    default float dtype). float16/bfloat16 cannot hold a pixel position to a useful
    precision (steps of 0.5 px at 1000 px): every epipolar distance is then wrong."""
    dtype = np.dtype(dtype)
    if jnp.issubdtype(dtype, jnp.integer) and dtype != np.bool_:
        return
    if not jnp.issubdtype(dtype, jnp.floating):
        raise ValueError(
            f"{name} must hold real pixel coordinates (float32 or float64); got dtype {dtype}"
        )
    if jnp.finfo(dtype).bits < 32:
        raise ValueError(
            f"{name} has dtype {dtype}, too coarse for pixel coordinates; use float32 or float64"
        )


def as_array(value):
    """Lists and other array-likes as NumPy arrays; JAX and NumPy arrays as they are."""
    return value if isinstance(value, (jax.Array, np.ndarray)) else np.asarray(value)


def _image_diagonal_from_K(K) -> float:
    """Twice the largest principal point ``K[:2, 2] / K[2, 2]`` over all views (pixels): the
    image diagonal when the principal point is near the image centre."""
    K = np.asarray(K, np.float64).reshape(-1, 3, 3)
    center = K[:, :2, 2] / K[:, 2:, 2]
    return float(2.0 * np.max(np.hypot(center[:, 0], center[:, 1])))


def _detections_extent(xy, mask) -> float:
    """``hypot(max |x|, max |y|)`` over the detections (pixels), 0 without detections."""
    xy_h, mask_h = np.asarray(xy), np.asarray(mask)
    if not mask_h.any():
        return 0.0
    return float(np.hypot(*np.abs(xy_h[mask_h]).max(axis=0)))


def check_sigma(sigma, rig: Rig, xy, mask, num_scenes: int | None = None) -> None:
    """σ is ``"auto"`` or a finite number ``0 <= σ <= D`` pixels (a ``(B,)`` array per scene
    when ``num_scenes`` is given); raises naming the value (and scene).

    ``D`` bounds any plausible detection noise by the image size, which ``associate`` is
    not given: the larger of twice the largest principal point of ``rig.K`` (the image
    diagonal when the principal point is central) and ``hypot(max |x|, max |y|)`` of the
    detections. Traced values are not checked.
    """
    if isinstance(sigma, str):
        if sigma != "auto":
            raise ValueError(f'sigma must be a number (pixels), an array or "auto"; got {sigma!r}')
        return
    if (
        sigma is None
        or isinstance(sigma, (bool, np.bool_))
        or not (isinstance(sigma, (numbers.Number, jax.Array, np.ndarray, np.generic, list, tuple)))
    ):
        want = (
            'a number (pixels), a (B,) array or "auto"'
            if num_scenes is not None
            else 'a number (pixels) or "auto"'
        )
        raise TypeError(f"sigma must be {want}; got {type(sigma).__name__} {sigma!r}")
    shape = tuple(np.shape(sigma))
    if num_scenes is None and shape != ():
        raise ValueError(
            f"sigma must be a scalar for one scene; got shape {shape} (use associate_batch for many)"
        )
    if num_scenes is not None and shape not in ((), (num_scenes,)):
        raise ValueError(
            f"sigma must be a scalar or have shape (B,) = ({num_scenes},), one per scene; got shape {shape}"
        )
    if isinstance(sigma, jax.core.Tracer):
        return
    host = np.asarray(sigma)
    if host.dtype == np.bool_ or not (
        np.issubdtype(host.dtype, np.floating) or np.issubdtype(host.dtype, np.integer)
    ):
        raise ValueError(f"sigma must be real; got dtype {host.dtype}")
    host = host.astype(np.float64)
    scene = lambda i: f" of scene {i}" if host.ndim else ""  # noqa: E731
    bad = ~np.isfinite(host) | (host < 0)
    if bad.any():
        i = int(np.argwhere(bad.reshape(-1))[0, 0])
        raise ValueError(
            f"sigma{scene(i)} must be a finite number >= 0 (pixels); got {float(host.reshape(-1)[i])!r}"
        )
    largest = float(host.max())
    if isinstance(rig.K, jax.core.Tracer) or largest == 0.0:
        return
    bound_K = _image_diagonal_from_K(rig.K)
    if largest <= bound_K:
        return
    bound_xy = _detections_extent(xy, mask) if _is_concrete(xy, mask) else 0.0
    if largest <= bound_xy:
        return
    i = int(np.argmax(host.reshape(-1)))
    if bound_K >= bound_xy:
        bound = f"the image diagonal {bound_K:.1f} px (twice the largest principal point of rig.K)"
    else:
        bound = f"the detections' extent {bound_xy:.1f} px (hypot of the largest |x| and |y|)"
    raise ValueError(
        f"sigma{scene(i)} = {largest!r} px is larger than {bound}; no detection noise can be that large"
    )


def check_threshold_shapes(thresholds, num_scenes: int | None) -> None:
    """Each threshold is a scalar, or (for a batch) a ``(B,)`` array."""
    allowed = ((),) if num_scenes is None else ((), (num_scenes,))
    for name, value in zip(type(thresholds)._fields, thresholds):
        if name != "sigma_px" and tuple(np.shape(value)) not in allowed:
            want = "a scalar" if num_scenes is None else f"a scalar or shape (B,) = ({num_scenes},)"
            raise ValueError(
                f"thresholds.{name} must be {want}; got shape {tuple(np.shape(value))}"
            )


def check_batch_rig(rig: Rig, num_scenes: int) -> None:
    """A per-scene rig ``K (B, M, 3, 3)`` has one camera set per scene of ``xy``."""
    if rig.K.ndim == 4 and rig.K.shape[0] != num_scenes:
        raise ValueError(
            f"the per-scene rig has {rig.K.shape[0]} scenes (rig.K shape {tuple(rig.K.shape)}) but xy has "
            f"B={num_scenes}; pass one rig per scene, or a shared rig with K of shape (M, 3, 3)"
        )
