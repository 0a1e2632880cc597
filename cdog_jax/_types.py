"""The array types every module annotates with (jaxtyping; dimension letters: B scenes,
M views, P slots per view, N = M*P nodes, G groups), and ``lift`` for explicit broadcasting."""

from typing import Union

import numpy as np
from jaxtyping import Array, Bool, Float, Int, UInt

# Public entry points accept NumPy arrays and nested lists too; internals take jax Arrays.
ArrayLike = Union[Array, np.ndarray, list, tuple]

__all__ = ["Array", "ArrayLike", "Bool", "Float", "Int", "UInt", "lift"]


def lift(a, ndim: int):  # noqa: D401
    """``a`` with leading singleton axes up to ``ndim`` dims, so that it broadcasts against an
    ``ndim``-dimensional array without implicit rank promotion."""
    return a.reshape((1,) * (ndim - a.ndim) + a.shape)
