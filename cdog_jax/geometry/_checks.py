"""Eager checks at the geometry functions' public entries: argument types and the shapes
that tie tracks to the rig's views. Shapes are static, so these run under ``jit`` too."""

from __future__ import annotations

import numpy as np

from .._expect import ARRAY, expect_args
from ._camera import Rig


def check_tracks(rig, xy, mask, weights, function: str) -> None:
    """``rig`` unbatched with ``M`` views; ``xy (M, *S, 2)``, bool ``mask (M, *S)`` and
    ``weights`` (when given) of the mask's shape."""
    expect_args(function, rig=(rig, Rig), xy=(xy, ARRAY), mask=(mask, ARRAY))
    if not hasattr(xy, "dtype"):
        raise TypeError(
            f"{function}: xy must be an array (NumPy or JAX), not a {type(xy).__name__}"
        )
    K_shape = tuple(np.shape(rig.K))
    if len(K_shape) != 3 or K_shape[1:] != (3, 3):
        raise ValueError(
            f"{function}: rig.K must have shape (M, 3, 3) (one rig; vmap over many); got {K_shape}"
        )
    M = K_shape[0]
    xy_shape, mask_shape = tuple(np.shape(xy)), tuple(np.shape(mask))
    if len(xy_shape) < 2 or xy_shape[0] != M or xy_shape[-1] != 2:
        raise ValueError(
            f"{function}: xy must have shape (M, *S, 2), the view axis first, with M={M} views from the rig; got {xy_shape}"
        )
    if mask_shape != xy_shape[:-1]:
        raise ValueError(
            f"{function}: mask must have shape {xy_shape[:-1]} (one flag per view of each track); got {mask_shape}"
        )
    mask_dtype = mask.dtype if hasattr(mask, "dtype") else np.asarray(mask).dtype
    if mask_dtype != np.bool_:
        raise ValueError(f"{function}: mask must be boolean; got dtype {mask_dtype}")
    if weights is not None:
        expect_args(function, weights=(weights, ARRAY))
        if tuple(np.shape(weights)) != mask_shape:
            raise ValueError(
                f"{function}: weights must have the shape of mask {mask_shape}; got {tuple(np.shape(weights))}"
            )
