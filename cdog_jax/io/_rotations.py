"""Exact host-side rotation conversions for the rig files (NumPy float64, one rotation).

Rodrigues vectors (axis × angle, as ``cv2.Rodrigues``) and unit quaternions (Hamilton,
``w`` first, as COLMAP) to and from 3×3 rotation matrices. They run on the host while a
file is read or written, so they are plain NumPy: no tracing, no gradients.
"""

from __future__ import annotations

import numpy as np


def _skew(v: np.ndarray) -> np.ndarray:
    """``[v]_x``, the 3×3 matrix of ``u ↦ v × u``."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def rotation_from_rodrigues(rvec: np.ndarray) -> np.ndarray:
    """The rotation matrix ``(3, 3)`` of a Rodrigues vector ``(3,)`` (angle ``|r|`` in radians
    about ``r / |r|``), as ``cv2.Rodrigues``: ``R = I + a [r]_x + b [r]_x²``."""
    r = np.asarray(rvec, dtype=np.float64).reshape(3)
    theta = float(np.sqrt(r @ r))
    # a = sin θ / θ and b = (1 - cos θ) / θ² = ½ (sin(θ/2) / (θ/2))², written with np.sinc so
    # that both are exact at θ = 0 and b has no cancellation for small θ.
    a = np.sinc(theta / np.pi)
    b = 0.5 * np.sinc(theta / (2 * np.pi)) ** 2
    S = _skew(r)
    return np.eye(3) + a * S + b * (S @ S)


def rodrigues_from_rotation(R: np.ndarray) -> np.ndarray:
    """The Rodrigues vector ``(3,)`` of a rotation matrix ``(3, 3)``, angle in ``[0, π]``.

    Goes through the unit quaternion (well conditioned for every angle, π included), then
    ``r = 2 atan2(|v|, w) v / |v|`` with ``w ≥ 0``.
    """
    q = quaternion_from_rotation(R)
    w, v = q[0], q[1:]
    s = float(np.sqrt(v @ v))
    if s < 1e-8:
        # atan2(s, w) / s = (1 / w)(1 - s²/(3w²) + …), with w ≈ 1 here: exact to float64.
        return v * (2.0 / w) * (1.0 - s * s / (3.0 * w * w))
    return v * (2.0 * np.arctan2(s, w) / s)


def rotation_from_quaternion(q: np.ndarray) -> np.ndarray:
    """The rotation matrix ``(3, 3)`` of a unit quaternion ``(w, x, y, z)`` (Hamilton)."""
    w, x, y, z = np.asarray(q, dtype=np.float64).reshape(4)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def quaternion_from_rotation(R: np.ndarray) -> np.ndarray:
    """The unit quaternion ``(w, x, y, z)`` (Hamilton, ``w ≥ 0``) of a rotation matrix.

    Shepperd's method: the square root is taken of the largest of ``4w², 4x², 4y², 4z²``,
    so no division is by a small number, whatever the angle.
    """
    R = np.asarray(R, dtype=np.float64).reshape(3, 3)
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    cands = np.array([tr, R[0, 0], R[1, 1], R[2, 2]])
    k = int(np.argmax(cands))
    if k == 0:
        s = 2.0 * np.sqrt(1.0 + tr)  # 4w
        q = np.array(
            [s / 4, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
        )
    elif k == 1:
        s = 2.0 * np.sqrt(max(1.0 + R[0, 0] - R[1, 1] - R[2, 2], 0.0))  # 4x
        q = np.array(
            [(R[2, 1] - R[1, 2]) / s, s / 4, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s]
        )
    elif k == 2:
        s = 2.0 * np.sqrt(max(1.0 - R[0, 0] + R[1, 1] - R[2, 2], 0.0))  # 4y
        q = np.array(
            [(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, s / 4, (R[1, 2] + R[2, 1]) / s]
        )
    else:
        s = 2.0 * np.sqrt(max(1.0 - R[0, 0] - R[1, 1] + R[2, 2], 0.0))  # 4z
        q = np.array(
            [(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, s / 4]
        )
    q = q / np.sqrt(q @ q)
    return -q if q[0] < 0 else q
