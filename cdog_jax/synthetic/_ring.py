"""A ring of cameras around a floor, for scenes of people (docs/BENCHMARK.md §7): the layout of
motion-capture rooms and of multi-person pose datasets (5 views, full-HD images)."""

from __future__ import annotations

import jax
import numpy as np

from .._expect import INT, expect
from ..geometry._camera import Rig
from ._rig import look_at_rotation

RING_IMAGE_SIZE: tuple[int, int] = (1920, 1080)
"""Image ``(width, height)`` of :func:`ring_rig` in pixels."""


def ring_rig(
    *,
    num_views: int = 5,
    radius: float = 5.0,
    height: float = 2.5,
    target_height: float = 1.0,
    focal_px: float = 1200.0,
    image_size: tuple[int, int] = RING_IMAGE_SIZE,
    dtype=None,
) -> Rig:
    """``num_views`` cameras evenly on a circle of ``radius`` (metres) around the origin,
    ``height`` above the floor ``z = 0``, each looking at ``(0, 0, target_height)``; focal
    ``focal_px``, principal point at the image centre, no roll. Deterministic.

    With the defaults a person standing within 1.5 m of the centre is in every image
    (half fields of view 39° × 24°); one 1 cm from the centre moves about 2.4 px.

    Returns a :class:`Rig` of ``(num_views, …)`` arrays of ``dtype`` (default: JAX's
    default float).
    """
    expect(num_views, INT, "num_views", "ring_rig")
    if num_views < 2:
        raise ValueError(f"num_views must be >= 2; got {num_views}")
    if not (radius > 0 and focal_px > 0):
        raise ValueError(f"radius and focal_px must be > 0; got {radius!r} and {focal_px!r}")
    dtype = np.dtype(dtype or jax.dtypes.canonicalize_dtype(np.float64))
    w, h = image_size
    K = np.array([[focal_px, 0.0, 0.5 * w], [0.0, focal_px, 0.5 * h], [0.0, 0.0, 1.0]])
    target = np.array([0.0, 0.0, target_height])
    Ks, Rs, ts = [], [], []
    for m in range(num_views):  # host-side constant
        angle = 2.0 * np.pi * m / num_views
        center = np.array([radius * np.cos(angle), radius * np.sin(angle), height])
        R = look_at_rotation(center, target)
        Ks.append(K)
        Rs.append(R)
        ts.append(-R @ center)
    return Rig(*(jax.device_put(np.asarray(a, dtype)) for a in (Ks, Rs, ts)))
