"""Visibility support of a group (beyond the paper; ``Config.support_filter``).

A real point is detected in (nearly) every view that sees it; a group made of clutter, or
of clutter and a stray detection, triangulates to a point that other views should see but
where they hold no detection. For every group, a view is *missing* when it is not a member
view, the group's point is in front of its camera and projects inside the view's
detection area, and no detection of the view lies within ``support_frac · τ`` pixels of the
projection. A group is dropped when its missing views are more than ``support_max_missing``
of the views that should see it (members + missing), or when its point is behind one of its
member cameras.

The pipeline is not told the image size: a view's detection area is the bounding box of
its valid detections (with clutter it is about the whole image; without it, the region
where points are seen). Views without a detection never count as missing.
"""

import jax.numpy as jnp

from .._config import Thresholds
from .._types import Array, Bool, Float
from ..geometry._camera import Rig
from ..geometry._projection import project


def missing_views(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    mask: Bool[Array, "M P"],
    X: Float[Array, "G 3"],
    member: Bool[Array, "G M"],
    radius_px: Float[Array, ""],
) -> tuple[Bool[Array, "G M"], Bool[Array, "G M"]]:
    """``(G, M)`` views where group ``g``'s point ``X[g]`` should be detected but is not, and
    ``(G, M)`` whether it is in front of each camera."""
    pix, in_front = project(rig, X)  # (G, M, 2), (G, M)
    lo = jnp.min(jnp.where(mask[..., None], xy, jnp.inf), axis=1)  # (M, 2); +inf: no detection
    hi = jnp.max(jnp.where(mask[..., None], xy, -jnp.inf), axis=1)
    inside = in_front & jnp.all((pix >= lo[None]) & (pix <= hi[None]), axis=-1)  # (G, M)
    diff = pix[:, :, None, :] - xy[None]  # (G, M, P, 2)
    near = jnp.any(mask[None] & (jnp.sum(diff * diff, axis=-1) < radius_px * radius_px), axis=-1)  # (G, M)
    return inside & ~member & ~near, in_front


def support_keep(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    mask: Bool[Array, "M P"],
    X: Float[Array, "G 3"],
    member: Bool[Array, "G M"],
    valid: Bool[Array, " G"],
    tau_px: Float[Array, ""],
    th: Thresholds,
) -> Bool[Array, " G"]:
    """``(G,)``: the valid groups that pass the visibility-support test (module docstring).

    Args:
        xy, mask: the scene's detections ``(M, P, 2)`` (pixels) and ``(M, P)``.
        X: ``(G, 3)`` each group's triangulated point; ``member (G, M)`` its member views.
        valid: ``(G,)`` groups to test; the result is a subset.
    """
    member = member & valid[:, None]
    missing, in_front = missing_views(rig, xy, mask, X, member, th.support_frac * tau_px)
    n_missing = jnp.sum(missing, axis=1, dtype=jnp.int32).astype(xy.dtype)
    n_member = jnp.sum(member, axis=1, dtype=jnp.int32).astype(xy.dtype)
    behind = jnp.any(member & ~in_front, axis=1)
    return valid & ~behind & (n_missing <= th.support_max_missing * (n_member + n_missing))
