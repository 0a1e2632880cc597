"""Lengths of short vectors (2D pixels, 3D points), summed coordinate by coordinate.

XLA's CPU backend hands a reduction over a last axis of two or three entries to a library
kernel that is far slower than plain arithmetic on such tables (a live frame's (256, 256, 3)
distance table took 0.67 ms as a sum, a few microseconds written out). The sum written out
runs in coordinate order; the library kernel's order differs, so the two can differ in the
last bit (``jnp.sum(v * v, axis=-1)`` is the same sum up to that rounding).
"""

import jax.numpy as jnp

from .._types import Array, Float


def squared_length(v: Float[Array, "*S D"]) -> Float[Array, "*S"]:
    """``Σ_k v[..., k]²`` over the last axis (a few coordinates), in coordinate order."""
    total = v[..., 0] * v[..., 0]
    for k in range(1, v.shape[-1]):
        total = total + v[..., k] * v[..., k]
    return total


def distance(a: Float[Array, "*#S D"], b: Float[Array, "*#S D"]) -> Float[Array, "..."]:
    """The Euclidean distance between ``a`` and ``b`` (broadcast) along their last axis
    (``jnp.linalg.norm(a - b, axis=-1)`` up to the last bit)."""
    return jnp.sqrt(squared_length(a - b))
