"""The camera rig (docs/CONVENTIONS.md §1): pinhole cameras with a general upper-triangular K.

World→camera: ``X_cam = R X_world + t``; pixels ``x ~ K X_cam``, always dehomogenised by
the third coordinate (K[2,2] may be negative). "In front" means ``X_cam[2] > 0``.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._expect import ARRAY, expect_args
from .._types import Array, Bool, Float, lift


class Rig(eqx.Module):
    """M calibrated pinhole cameras. A batch of rigs adds leading axes to every field.

    Attributes:
        K: ``(M, 3, 3)`` intrinsics, general upper-triangular (``K[2,2]`` may be -1).
        R: ``(M, 3, 3)`` world→camera rotations.
        t: ``(M, 3)`` world→camera translations (scene units).
    """

    K: Float[Array, "*B M 3 3"]
    R: Float[Array, "*B M 3 3"]
    t: Float[Array, "*B M 3"]

    @property
    def num_views(self) -> int:
        return self.K.shape[-3]

    @property
    def proj(self) -> Float[Array, "M 3 4"]:
        """Projection matrices ``K [R | t]``, ``(M, 3, 4)``."""
        return jnp.einsum(
            "...ij,...jk->...ik", self.K, jnp.concatenate([self.R, self.t[..., None]], -1)
        )

    def host_proj(self) -> np.ndarray:
        """:attr:`proj` computed in float64 by NumPy, ``(M, 3, 4)``: for the host-side
        (NumPy) methods and checks, which must not round the cameras to float32 first."""
        K, R, t = (np.asarray(a, np.float64) for a in (self.K, self.R, self.t))
        return np.einsum("...ij,...jk->...ik", K, np.concatenate([R, t[..., None]], -1))

    @property
    def centers(self) -> Float[Array, "M 3"]:
        """Camera centres in world coordinates, ``C = -Rᵀ t``, ``(M, 3)``."""
        return -jnp.einsum("...ji,...j->...i", self.R, self.t)

    @property
    def view_dirs(self) -> Float[Array, "M 3"]:
        """Optical axes in world coordinates (unit), ``(M, 3)``: the third row of R."""
        return self.R[..., 2, :]

    def centers_and_dirs_on_host(self) -> tuple[np.ndarray, np.ndarray]:
        """:attr:`centers` and :attr:`view_dirs` in NumPy float64, ``(M, 3)`` each: for code
        outside ``jit`` (figures, reports), where the properties would each compile a small
        program."""
        R, t = np.asarray(self.R, dtype=np.float64), np.asarray(self.t, dtype=np.float64)
        return centres_on_host(R, t), R[..., 2, :]

    def select(self, views) -> Rig:
        """The sub-rig of the given view indices (a sequence or an int array; negative
        indices count from the end). Raises ``ValueError`` for an index out of range (JAX
        would clamp it to the last view)."""
        views = np.asarray(views)
        M = int(np.shape(self.K)[-3])
        if views.dtype == bool or not np.issubdtype(views.dtype, np.integer):
            raise ValueError(f"Rig.select: view indices must be integers; got dtype {views.dtype}")
        out = (views < -M) | (views >= M)
        if out.any():
            raise ValueError(
                f"Rig.select: view index {int(views[out].flat[0])} is out of range for a rig of {M} views"
            )
        return Rig(self.K[..., views, :, :], self.R[..., views, :, :], self.t[..., views, :])


def cannot_change(*arrays) -> bool:
    """Whether every one of ``arrays`` is a JAX array, whose values cannot change in place:
    what is read or computed from it may be kept while the same object comes back (a frame
    loop on one rig). A NumPy array can change between two calls and is read every time."""
    return all(isinstance(a, jax.Array) for a in arrays)


def centres_on_host(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Camera centres ``C = -Rᵀ t`` in NumPy, ``(..., M, 3)`` from ``R (..., M, 3, 3)`` and
    ``t (..., M, 3)`` (in their dtype: float64 where a rig is built or read)."""
    return -np.einsum("...ji,...j->...i", R, t)


def _check_camera_dtype(dtype, name: str) -> None:
    """Cameras are real numbers of at least 32 bits (integers are converted): float16 and
    bfloat16 have already rounded a focal length or a translation to 3 significant digits,
    which moves every epipolar line by pixels."""
    dtype = np.dtype(dtype)
    if dtype != np.bool_ and jnp.issubdtype(dtype, jnp.integer):
        return
    if not jnp.issubdtype(dtype, jnp.floating):
        raise ValueError(f"rig_from_arrays: {name} must hold real numbers; got dtype {dtype}")
    if jnp.finfo(dtype).bits < 32:
        raise ValueError(
            f"rig_from_arrays: {name} has dtype {dtype}, too coarse for a camera (about 3 "
            "significant digits); give float32 or float64"
        )


ROUNDING_PX_LIMIT = 0.05
"""The most a rig's rounding to its float type may move an epipolar line (pixels, an upper
estimate): beyond it :func:`rig_from_arrays` asks for an ``origin`` near the cameras."""


def rounding_px(K: np.ndarray, R: np.ndarray, t: np.ndarray, dtype) -> float:
    """How far (pixels, an upper estimate) rounding the cameras' positions to ``dtype`` moves
    an epipolar line: a camera centre ``C`` is held to ``|C| · ε/2`` (ε: the type's
    precision), which moves a point at depth ``Z`` by the focal length times ``|C| ε/2 / Z``.
    ``Z``: where the optical axes meet (the scene of a rig around it), at least the cameras'
    spread (their RMS distance to their mean centre; also where the axes do not meet, as
    for parallel stereo). Scale-free: a rig in millimetres rounds as one in metres; a rig
    far from its world origin (UTM-like coordinates) rounds by pixels in float32."""
    C = centres_on_host(R, t)
    spread = float(np.sqrt(((C - C.mean(axis=0)) ** 2).sum(axis=1).mean()))
    if not spread > 0:  # one camera, or all in one place: nothing to compare with
        return 0.0
    depth = spread
    axes = R[:, 2, :] * np.sign(K[:, 2, 2])[:, None]  # optical axes, toward what is seen
    across = np.eye(3) - np.einsum("mi,mj->mij", axes, axes)  # projections off each axis
    A, b = across.sum(axis=0), np.einsum("mij,mj->i", across, C)
    if np.linalg.cond(A) < 1e6:
        meet = np.linalg.solve(A, b)  # the point nearest every optical axis
        ahead = np.einsum("mi,mi->m", meet - C, axes)
        if (ahead > 0).all():
            depth = max(spread, float(np.median(ahead)))
    focal = float(np.median(np.abs(K[:, [0, 1], [0, 1]] / K[:, 2:3, 2]).max(axis=1)))
    return focal * float(np.abs(C).max()) * float(np.finfo(dtype).eps) / 2 / depth


def rig_from_arrays(K, R, t, *, dtype=None, origin=None) -> Rig:
    """Build a :class:`Rig` from array-likes, with eager shape and value checks.

    ``K (M, 3, 3)``, ``R (M, 3, 3)``, ``t (M, 3)``. ``origin``: ``(3,)`` a world point
    (scene units) that becomes the rig's origin, subtracted in float64 before the rig is
    rounded to ``dtype``: the rig, and every 3D point of its associations, are then in
    world coordinates less ``origin`` (add it back to them).

    Raises ``ValueError`` naming the offending view for wrong shapes, non-finite values, a
    singular ``K``, a ``K`` that is not upper-triangular or whose focal lengths are not
    positive (relative to ``K[2, 2]``: a transposed or mirrored ``K``), a rotation that is
    not orthonormal (tolerance 1e-3), or a ``dtype`` other than float32 and float64, or
    inputs of float16, bfloat16, bool or complex (integer arrays are converted); and for
    cameras so far from the origin that ``dtype`` cannot hold their positions (rounding
    would move epipolar lines by more than :data:`ROUNDING_PX_LIMIT` pixels: UTM-like
    coordinates in float32), naming the ``origin`` to give.
    """
    expect_args("rig_from_arrays", K=(K, ARRAY), R=(R, ARRAY), t=(t, ARRAY))
    dtype = np.dtype(dtype or jnp.asarray(0.0).dtype)
    if dtype not in (np.dtype(np.float32), np.dtype(np.float64)):
        raise ValueError(
            f"rig_from_arrays: dtype must be float32 or float64; got {dtype} (too few digits for pixels at a distance)"
        )
    for name, value in (("K", K), ("R", R), ("t", t)):
        _check_camera_dtype(
            value.dtype if hasattr(value, "dtype") else np.asarray(value).dtype, name
        )
    K, R, t = (np.asarray(a, dtype=np.float64) for a in (K, R, t))
    if K.ndim != 3 or K.shape[1:] != (3, 3):
        raise ValueError(f"K must have shape (M, 3, 3); got {K.shape}")
    M = K.shape[0]
    if R.shape != (M, 3, 3):
        raise ValueError(f"R must have shape (M, 3, 3) with M={M} from K; got {R.shape}")
    if t.shape != (M, 3):
        raise ValueError(f"t must have shape (M, 3) with M={M} from K; got {t.shape}")
    check_rig_values(K, R, t)
    if origin is not None:
        origin = np.asarray(origin, dtype=np.float64)
        if origin.shape != (3,) or not np.isfinite(origin).all():
            raise ValueError(f"origin must be 3 finite numbers (x, y, z); got {origin.tolist()}")
        t = t + np.einsum("mij,j->mi", R, origin)  # X_cam = R (X - origin) + t'
    px = rounding_px(K, R, t, dtype)
    if px > ROUNDING_PX_LIMIT:
        C = centres_on_host(R, t)
        centre = C.mean(axis=0) + (0.0 if origin is None else origin)
        raise ValueError(
            f"the cameras lie {np.abs(C).max():.3g} units from the "
            f"world origin, where {dtype.name} rounds their positions by up to "
            f"{px:.2g} px of epipolar distance: give a world point near them as origin= (their mean "
            f"centre: origin=({centre[0]:.6f}, {centre[1]:.6f}, {centre[2]:.6f})) and add it to "
            "the 3D points"
        )
    return Rig(jnp.asarray(K, dtype), jnp.asarray(R, dtype), jnp.asarray(t, dtype))


def check_rig_values(K: np.ndarray, R: np.ndarray, t: np.ndarray) -> None:
    """Eager value checks on host arrays; raises ``ValueError`` naming the first bad view."""
    for name, a in (("K", K), ("R", R), ("t", t)):
        bad = ~np.isfinite(a).reshape(a.shape[0], -1).all(axis=1)
        if bad.any():
            raise ValueError(f"{name} of view {int(np.argmax(bad))} has non-finite entries")
    det_K = np.linalg.det(K)
    scale = np.abs(K).max(axis=(1, 2)) ** 3
    singular = np.abs(det_K) <= 1e-12 * np.maximum(scale, 1e-300)
    if singular.any():
        m = int(np.argmax(singular))
        raise ValueError(f"K of view {m} is singular (det = {det_K[m]:.3g})")
    size = np.abs(K).max(axis=(1, 2))
    below = np.abs(K[:, [1, 2, 2], [0, 0, 1]]).max(axis=1)
    lower = below > 1e-9 * size
    if lower.any():
        m = int(np.argmax(lower))
        raise ValueError(
            f"K of view {m} is not upper-triangular (below the diagonal: {K[m][1, 0]:.6g}, {K[m][2, 0]:.6g}, "
            f"{K[m][2, 1]:.6g}); a transposed K? (MATLAB's IntrinsicMatrix is Kᵀ)"
        )
    mirrored = (K[:, 0, 0] * K[:, 2, 2] <= 0) | (K[:, 1, 1] * K[:, 2, 2] <= 0)
    if mirrored.any():
        m = int(np.argmax(mirrored))
        raise ValueError(
            f"K of view {m} has a focal length that is not positive (fx = {K[m][0, 0]:.6g}, fy = {K[m][1, 1]:.6g}, "
            f"K[2, 2] = {K[m][2, 2]:.6g}); a mirrored camera cannot be right"
        )
    ortho_err = np.abs(np.einsum("mji,mjk->mik", R, R) - np.eye(3)).max(axis=(1, 2))
    det_R = np.linalg.det(R)
    bad = (ortho_err > 1e-3) | (det_R < 0)
    if bad.any():
        m = int(np.argmax(bad))
        raise ValueError(
            f"R of view {m} is not a rotation (max |RᵀR - I| = {ortho_err[m]:.3g}, det = {det_R[m]:.3g})"
        )


def affine_per_view(
    A: Float[Array, "M R 3"], b: Float[Array, "M R"], X: Float[Array, "*S 3"]
) -> Float[Array, "*S M R"]:
    """``A_m X + b_m`` for every view m, ``(*S, M, R)`` (R output rows, e.g. 3).

    Written as three broadcast multiply-adds rather than an einsum: with a contraction of
    size 3, XLA's CPU dot is several times slower than plain elementwise arithmetic.
    """
    nd = X.ndim + 1  # (*S, M, R)
    Xe = X[..., None, :]  # (*S, 1, 3)
    out = lift(b, nd)
    for j in range(3):
        out = out + Xe[..., j : j + 1] * lift(A[:, :, j], nd)
    return out


def camera_points(rig: Rig, X_world: Float[Array, "*S 3"]) -> Float[Array, "M *S 3"]:
    """World points in every camera frame: ``X_cam = R X + t``, shape ``(M, *S, 3)`` (the
    view axis first)."""
    expect_args("camera_points", rig=(rig, Rig), X_world=(X_world, ARRAY))
    return jnp.moveaxis(affine_per_view(rig.R, rig.t, X_world), -2, 0)


def in_front(rig: Rig, X_world: Float[Array, "*S 3"]) -> Bool[Array, M * S]:
    """Whether each point lies in front of each camera, ``(R X + t)_z > 0``, ``(M, *S)``."""
    expect_args("in_front", rig=(rig, Rig), X_world=(X_world, ARRAY))
    return camera_points(rig, X_world)[..., 2] > 0
