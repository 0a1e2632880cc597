"""Homogeneous ↔ Euclidean conversions that divide by ``w`` honestly (no sign-blind epsilon)."""

import jax.numpy as jnp

from .._expect import ARRAY, expect_args
from .._types import Array, Bool, Float


def points_from_homogeneous(
    h: Float[Array, "*S 3"],
) -> tuple[Float[Array, "*S 2"], Bool[Array, "*S"]]:
    """``(x/w, y/w)`` of ``h (*S, 3)`` as ``(*S, 2)``, and a flag ``(*S,)`` that ``w != 0``;
    where ``w == 0`` the point is 0 and the flag False.

    The division uses the safe-where pattern so that values and gradients stay finite.
    """
    expect_args("points_from_homogeneous", h=(h, ARRAY))
    w = h[..., 2]
    ok = jnp.abs(w) > jnp.finfo(h.dtype).tiny
    safe_w = jnp.where(ok, w, 1.0)
    xy = h[..., :2] / safe_w[..., None]
    return jnp.where(ok[..., None], xy, 0.0), ok


def homogeneous_from_points(xy: Float[Array, "*S 2"]) -> Float[Array, "*S 3"]:
    """Append a 1: ``(*S, 2) → (*S, 3)``, ``(x, y) → (x, y, 1)``."""
    expect_args("homogeneous_from_points", xy=(xy, ARRAY))
    return jnp.concatenate([xy, jnp.ones_like(xy[..., :1])], axis=-1)
