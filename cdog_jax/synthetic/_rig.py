"""The built-in benchmark rig (docs/BENCHMARK.md §1): ten cameras in the style of the EasyVis
laparoscopic box trainer, plus a helper that negates K like OpenMVG exports (docs/CONVENTIONS.md §1).

The rig is a constant, built on the host with numpy and returned as a :class:`Rig` of
``jnp`` arrays. World frame: ``z`` up, the workspace box ``DEFAULT_BOX`` centred on the
origin in ``x, y`` and standing on ``z = 0``; every camera sits above the box top.
"""

from __future__ import annotations

import jax
import numpy as np

from .._expect import ARRAY, INT, expect_args
from ..geometry._camera import Rig

IMAGE_SIZE: tuple[int, int] = (640, 480)
"""Image ``(width, height)`` in pixels."""

DEFAULT_BOX: tuple[tuple[float, float, float], tuple[float, float, float]] = (
    (-1.0, -0.75, 0.0),
    (1.0, 0.75, 0.5),
)
"""Lower and upper corners of the workspace box (scene units) in which points are sampled."""

FOCAL_PX = 1302.0
"""Nominal focal length of the built-in rig (pixels)."""

# Layout of the cap of cameras; all angles in degrees, distances in scene units. These
# numbers were tuned so that a uniform point of DEFAULT_BOX is seen by ~4.8 of 10 views.
_SEED = 2507_14095
_ELEVATION_DEG = (42.0, 68.0)  # alternating low / high ring
_DISTANCE = (2.2, 3.2)  # camera centre to box centre, alternating near / far
_AZIMUTH_JITTER_DEG = 8.0
_ELEVATION_JITTER_DEG = 5.0
_DISTANCE_JITTER = 0.25
_TARGET_OFFSET = (0.3, 0.25, 0.1)  # max |offset| of the look-at point from the box centre
_ROLL_DEG = 12.0
_FOCAL_JITTER_PX = 6.0
_PRINCIPAL_JITTER_PX = (6.0, 5.0)


def look_at_rotation(center, target, *, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """World→camera rotation ``(3, 3)`` (numpy, float64) of a camera at ``center`` looking at
    ``target`` (both ``(3,)``, world frame), OpenCV axes: x right, y down, z forward.

    ``up`` is the world direction that should point up in the image; it must not be
    parallel to the viewing direction.
    """
    expect_args("look_at_rotation", center=(center, ARRAY), target=(target, ARRAY))
    center, target, up = (np.asarray(a, dtype=np.float64) for a in (center, target, up))
    z = target - center
    z = z / np.linalg.norm(z)
    x = np.cross(z, up)
    norm_x = np.linalg.norm(x)
    if norm_x < 1e-9:
        raise ValueError(f"up {up.tolist()} is parallel to the viewing direction {z.tolist()}")
    x = x / norm_x
    y = np.cross(z, x)
    return np.stack([x, y, z])


def _roll(R: np.ndarray, roll_rad: float) -> np.ndarray:
    """Rotate the camera about its own optical axis by ``roll_rad``."""
    c, s = np.cos(roll_rad), np.sin(roll_rad)
    Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return Rz @ R


def default_rig(*, num_views: int = 10, dtype=None) -> Rig:
    """The built-in synthetic rig: ``num_views`` cameras on a cap above ``DEFAULT_BOX``.

    640×480 images, focal ≈ 1302 px (±6 px per camera), principal point ≈ (320, 240)
    (±6, ±5 px), ``K[2,2] = 1``. Camera centres lie 2.0–3.4 units from the box centre
    (1.3–4.3 units from the points of the box), 1.7–3.4 units above the box floor,
    azimuths spread evenly around the box, elevations alternating about 42° and 68°, each
    camera looking at a point up to 0.3 units off the box centre, rolled by up to ±12°.
    Deterministic (a fixed seed).

    Measured with 10 views: a point uniform in ``DEFAULT_BOX`` is in front of and inside
    the image of 4.81 views on average (4 samples of 2,000,000 points: 4.80–4.81), and 81 %
    of the points are seen by ≥ 2 views (so ``generate_scene``'s default oversampling of 4
    is ample). For fewer views in an ablation, prefer ``default_rig().select(views)``,
    which keeps the cameras of the full rig.

    Returns:
        A :class:`Rig` of ``(num_views, …)`` arrays of ``dtype`` (default: JAX's default
        float, float32 unless x64 is enabled).
    """
    expect_args("default_rig", num_views=(num_views, INT))
    if num_views < 1:
        raise ValueError(f"num_views must be >= 1; got {num_views}")
    dtype = np.dtype(dtype or jax.dtypes.canonicalize_dtype(np.float64))
    rng = np.random.default_rng(_SEED)
    lo, hi = (np.asarray(c, dtype=np.float64) for c in DEFAULT_BOX)
    box_center = 0.5 * (lo + hi)
    w, h = IMAGE_SIZE

    K = np.zeros((num_views, 3, 3))
    R = np.zeros((num_views, 3, 3))
    t = np.zeros((num_views, 3))
    for m in range(num_views):  # host-side constant: a Python loop is fine here
        u = rng.uniform(-1.0, 1.0, size=9)
        azimuth = np.deg2rad(360.0 * m / num_views + _AZIMUTH_JITTER_DEG * u[0])
        elevation = np.deg2rad(_ELEVATION_DEG[m % 2] + _ELEVATION_JITTER_DEG * u[1])
        distance = _DISTANCE[(m // 2) % 2] + _DISTANCE_JITTER * u[2]
        direction = np.array(
            [
                np.cos(elevation) * np.cos(azimuth),
                np.cos(elevation) * np.sin(azimuth),
                np.sin(elevation),
            ]
        )
        center = box_center + distance * direction
        target = box_center + np.asarray(_TARGET_OFFSET) * u[3:6]
        R[m] = _roll(look_at_rotation(center, target), np.deg2rad(_ROLL_DEG * u[6]))
        t[m] = -R[m] @ center
        f = FOCAL_PX + _FOCAL_JITTER_PX * u[7]
        cx = 0.5 * w + _PRINCIPAL_JITTER_PX[0] * u[8]
        cy = 0.5 * h + _PRINCIPAL_JITTER_PX[1] * rng.uniform(-1.0, 1.0)
        K[m] = [[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]]
    # device_put of host arrays: a JAX conversion would compile a program per shape.
    return Rig(*(jax.device_put(np.asarray(a, dtype)) for a in (K, R, t)))


def negate_intrinsics(rig: Rig, views) -> Rig:
    """An equivalent rig in which ``K (M, 3, 3)`` of the given views is multiplied by -1.

    Then ``K[2,2] = -1`` as in OpenMVG/EasyVis exports; pixels are unchanged because the
    projection is divided by the third homogeneous coordinate. ``views`` is a sequence or
    an int array of view indices. For tests of general-``K`` handling.
    """
    expect_args("negate_intrinsics", rig=(rig, Rig), views=(views, ARRAY))
    views = np.asarray(views, dtype=np.int32).reshape(-1)
    K = rig.K.at[..., views, :, :].multiply(-1)
    return Rig(K, rig.R, rig.t)
