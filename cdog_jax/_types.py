"""Shape aliases shared by all modules (dimension letters: B scenes, M views, P slots per
view, N = M*P nodes, G groups)."""

from typing import Union

import numpy as np
from jaxtyping import Array, Bool, Float, Int, UInt

# Public entry points accept NumPy arrays and nested lists too; internals take jax Arrays.
ArrayLike = Union[Array, np.ndarray, list, tuple]

Scalar = Float[Array, ""]
Mat3 = Float[Array, "M 3 3"]
Vec3 = Float[Array, "M 3"]
Pixels = Float[Array, "M P 2"]
Mask = Bool[Array, "M P"]
Labels = Int[Array, "M P"]

__all__ = ["Array", "ArrayLike", "Bool", "Float", "Int", "UInt", "Scalar", "Mat3", "Vec3", "Pixels", "Mask", "Labels", "lift"]


def lift(a, ndim: int):  # noqa: D401
    """``a`` with leading singleton axes up to ``ndim`` dims, so that it broadcasts against an
    ``ndim``-dimensional array without implicit rank promotion."""
    return a.reshape((1,) * (ndim - a.ndim) + a.shape)
