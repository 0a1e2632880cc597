"""Eager checks at the API boundary: shapes, dtypes and values, before any work.

Messages say what was expected, what arrived and where (view and slot). Inside ``jit``
(traced inputs) value checks are impossible and skipped; shape checks always run.
"""

from __future__ import annotations

import jax
import numpy as np

from .geometry._camera import Rig, check_rig_values


def _is_concrete(*arrays) -> bool:
    return not any(isinstance(a, jax.core.Tracer) for a in arrays)


def check_rig(rig: Rig, batched: bool = False) -> None:
    """Shapes of a (possibly per-scene batched) rig, and its values when concrete."""
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
            return
        for b in range(K.shape[0]):
            try:
                check_rig_values(K[b], R[b], t[b])
            except ValueError as e:
                raise ValueError(f"rig of scene {b}: {e}") from None


def check_observations(xy, mask, num_views: int, batched: bool = False) -> None:
    """``xy (…, M, P, 2)`` float and ``mask (…, M, P)`` bool; finite where valid."""
    lead = 1 if batched else 0
    xy_shape, mask_shape = tuple(np.shape(xy)), tuple(np.shape(mask))
    want_xy = "(B, M, P, 2)" if batched else "(M, P, 2)"
    if len(xy_shape) != 3 + lead or xy_shape[-1] != 2 or xy_shape[-3] != num_views:
        raise ValueError(f"xy must have shape {want_xy} with M={num_views} from the rig; got {xy_shape}")
    if xy_shape[-2] < 1:
        raise ValueError(f"xy must have at least one slot per view (P >= 1); got {xy_shape}")
    if mask_shape != xy_shape[:-1]:
        raise ValueError(f"mask must have shape {xy_shape[:-1]} to match xy {xy_shape}; got {mask_shape}")
    if np.dtype(getattr(mask, "dtype", np.asarray(mask).dtype)) != np.bool_:
        raise ValueError(f"mask must be boolean; got dtype {np.asarray(mask).dtype}")
    if _is_concrete(xy, mask):
        xy_h, mask_h = np.asarray(xy), np.asarray(mask)
        bad = mask_h & ~np.isfinite(xy_h).all(axis=-1)
        if bad.any():
            where = tuple(int(i) for i in np.argwhere(bad)[0])
            label = "scene {}, view {}, slot {}" if batched else "view {}, slot {}"
            raise ValueError(f"xy is not finite at {label.format(*where)} although mask is True there")
