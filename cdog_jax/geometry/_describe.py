"""A plain-language summary of a rig, with warnings that make a wrong rig obvious.

A reporting tool, not a pipeline stage: everything is converted to NumPy (float64) on the
host and nothing here is traced. The conventions are docs/CONVENTIONS.md §1: world→camera
``X_cam = R X + t``, centre ``C = -Rᵀ t``, optical axis = third row of ``R``, "in front"
means ``X_cam[2] > 0``; ``K`` is read as ``K / K[2,2]`` (so ``K[2,2] = -1`` is fine).

The warnings look for what a mix-up of conventions produces: cameras looking away from
the detections, optical axes that meet behind the cameras (typical of ``R, t`` given
camera→world), duplicated cameras, mirrored intrinsics; and near-zero baselines (a pair
of cameras whose baseline subtends less than ``Config.min_parallax_deg`` at the scene).
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from .._expect import expect_args
from ..cdog._config import DEFAULT_MIN_PARALLAX_DEG
from ._camera import Rig
from ._distortion import Fisheye, undistort_pixels


@dataclasses.dataclass(frozen=True)
class RigDescription:
    """The facts :meth:`Rig.describe` prints, as host NumPy data (float64).

    Attributes:
        names: ``M`` view names.
        centers: ``(M, 3)`` camera centres (scene units).
        view_dirs: ``(M, 3)`` unit optical axes (world frame).
        focal_px: ``(M, 2)`` ``(fx, fy)`` of ``K / K[2,2]`` (pixels).
        principal_px: ``(M, 2)`` ``(cx, cy)`` of ``K / K[2,2]`` (pixels).
        image_size: ``(M, 2)`` ``(width, height)`` in pixels, or None if not given.
        baseline_min, baseline_median, baseline_max: pairwise centre distances (scene
            units); NaN for a single view.
        closest_pair: the two views with the shortest baseline, or None for a single view.
        axes_point: ``(3,)`` least-squares point nearest to all optical axes (scene units),
            or None (one view, or all axes parallel).
        axes_point_in_front: ``(M,)`` bool, ``axes_point`` is in front of the camera.
        centroid: ``(3,)`` least-squares point nearest to the rays through every view's
            mean (undistorted) detection, or None (no detections given, or < 2 views with
            detections, or parallel rays).
        centroid_views: ``(M,)`` bool, the views whose ray went into ``centroid``.
        centroid_angle_deg: ``(M,)`` angle between each optical axis and the direction
            from the camera to ``centroid`` (degrees; NaN without a centroid).
        centroid_pixel: ``(M, 2)`` ``centroid`` projected into every view (pixels; NaN
            without a centroid or where it is behind the camera).
        warnings: one sentence per problem found; empty for a healthy rig.
        camera_to_world: the cameras point wrong as given (away from the detections, or
            their axes meet behind them) and right when ``R, t`` are read as camera→world:
            the rig was almost surely written in the other convention (a warning says so;
            the command line refuses such a rig).
    """

    names: list[str]
    centers: np.ndarray
    view_dirs: np.ndarray
    focal_px: np.ndarray
    principal_px: np.ndarray
    image_size: np.ndarray | None
    baseline_min: float
    baseline_median: float
    baseline_max: float
    closest_pair: tuple[int, int] | None
    axes_point: np.ndarray | None
    axes_point_in_front: np.ndarray
    centroid: np.ndarray | None
    centroid_views: np.ndarray
    centroid_angle_deg: np.ndarray
    centroid_pixel: np.ndarray
    warnings: list[str]
    camera_to_world: bool = False

    def format(self) -> str:
        """The multi-line text of :meth:`Rig.describe`."""
        return _format(self)

    def __str__(self) -> str:
        return _format(self)


def describe_rig(
    rig: Rig, *, xy=None, mask=None, image_size=None, names=None, dist=None
) -> RigDescription:
    """Centres, viewing directions, intrinsics, baselines and sanity warnings of one rig.

    Args:
        rig: one (unbatched) rig of ``M`` views.
        xy: optional ``(M, P, 2)`` detections (pixels) of one scene; they locate the scene
            (``centroid``) without any association, so that cameras looking away from it
            are flagged.
        mask: optional ``(M, P)`` bool, slot holds a detection (default: every slot of
            ``xy``).
        image_size: optional ``(width, height)`` in pixels, shared, or ``(M, 2)`` per view;
            then a camera whose image does not contain the centroid is flagged too.
        names: optional ``M`` view names (default ``"0" … "M-1"``).
        dist: optional ``(M, 5)`` OpenCV distortion ``(k1, k2, p1, p2, k3)``; detections
            are undistorted before their rays are cast.

    Returns:
        A :class:`RigDescription`; ``str()`` of it is the text of :meth:`Rig.describe`.
    """
    expect_args("describe_rig", rig=(rig, Rig))
    K, R, t, names = host_views(rig, names, "describe")
    sizes = image_sizes(image_size, K.shape[0])
    if xy is not None and dist is not None:
        xy = _undistorted(K, xy, mask, dist, rig.K.dtype)
    desc, pointing = _describe(K, R, t, xy, mask, sizes, names)
    if pointing:
        # Try the other convention: if R, t were camera→world, world→camera is (Rᵀ, −Rᵀ t).
        R_inv = np.swapaxes(R, 1, 2)
        inv, pointing_inv = _describe(
            K, R_inv, -np.einsum("mij,mj->mi", R_inv, t), xy, mask, sizes, names
        )
        checked = inv.centroid is not None or inv.axes_point is not None  # else nothing was tested
        if checked and not pointing_inv:
            desc = dataclasses.replace(desc, camera_to_world=True)
            desc.warnings.append(
                "read as camera→world (world→camera R' = Rᵀ, t' = −Rᵀ t), the same rig has none of "
                "these pointing problems: R, t were probably given camera→world; this library "
                "expects world→camera, X_cam = R X + t"
            )
    return desc


def _undistorted(K, xy, mask, dist, dtype) -> np.ndarray:
    """Detections ``(M, P, 2)`` undistorted on the device, as float64 host data."""
    xy = np.asarray(xy, dtype=np.float64)
    if mask is not None:
        xy = np.where(
            np.asarray(mask, dtype=bool)[..., None], xy, 0.0
        )  # padded slots may hold garbage
    if isinstance(dist, Fisheye):
        lens = Fisheye(jnp.asarray(dist.coeffs, dtype))  # undistort_pixels checks its shape
    else:
        dist = np.asarray(dist, dtype=np.float64)
        if dist.shape != (K.shape[0], 5):
            raise ValueError(f"dist must have shape (M, 5) with M={K.shape[0]}; got {dist.shape}")
        lens = jnp.asarray(dist, dtype)
    out = undistort_pixels(jnp.asarray(K, dtype), lens, jnp.asarray(xy, dtype))
    return np.asarray(out, dtype=np.float64)


def _describe(K, R, t, xy, mask, sizes, names) -> tuple[RigDescription, int]:
    """The description of host arrays, and how many of its warnings are pointing problems
    (cameras looking away, axes converging behind the cameras)."""
    M = K.shape[0]
    warnings: list[str] = []
    pointing = 0

    Kn = K / K[:, 2:3, 2:3]
    focal = np.stack([Kn[:, 0, 0], Kn[:, 1, 1]], axis=-1)
    principal = np.stack([Kn[:, 0, 2], Kn[:, 1, 2]], axis=-1)
    centers = -np.einsum("mji,mj->mi", R, t)
    dirs = R[:, 2, :] / np.linalg.norm(R[:, 2, :], axis=-1, keepdims=True)

    for m in np.flatnonzero((focal <= 0).any(axis=-1)):
        warnings.append(
            f"view {names[m]}: K / K[2,2] has a non-positive focal length (fx, fy = {focal[m, 0]:.1f}, "
            f"{focal[m, 1]:.1f} px): a mirrored image axis, or K given with the wrong sign convention"
        )

    # Baselines.
    dist_cc = np.linalg.norm(centers[:, None, :] - centers[None, :, :], axis=-1)  # (M, M)
    iu, ju = np.triu_indices(M, k=1)
    if M >= 2:
        pairs = dist_cc[iu, ju]
        k = int(np.argmin(pairs))
        b_min, b_med, b_max = float(pairs[k]), float(np.median(pairs)), float(pairs.max())
        closest = (int(iu[k]), int(ju[k]))
        # "Same centre" relative to the scene's scale, so that mm and m rigs behave alike.
        tol = 1e-6 * max(float(np.abs(centers).max()), b_max, 1e-12)
        for i, j, d in zip(iu, ju, pairs):
            if d <= tol:
                warnings.append(
                    f"views {names[i]} and {names[j]} have the same centre {_vec(centers[i])} "
                    f"(distance {d:.3g}): a duplicated camera (copied calibration?)"
                )
    else:
        b_min = b_med = b_max = float("nan")
        closest = None

    # The point nearest to all optical axes.
    axes_point = _nearest_point(centers, dirs) if M >= 2 else None
    axes_front = np.zeros(M, bool) if axes_point is None else _in_front(R, t, axes_point)
    if axes_point is not None and 2 * int(axes_front.sum()) <= M:
        behind = [names[m] for m in np.flatnonzero(~axes_front)]
        warnings.append(
            f"the optical axes do not converge in front of most cameras: their nearest point "
            f"{_vec(axes_point)} is behind {len(behind)} of {M} (views {', '.join(behind)}); "
            f"typical of R, t given camera→world instead of world→camera (X_cam = R X + t)"
        )
        pointing += 1
        axes_converge = False
    else:
        axes_converge = axes_point is not None

    # The detections' centroid: rays through every view's mean detection.
    centroid, centroid_views = None, np.zeros(M, bool)
    angle = np.full(M, np.nan)
    pixel = np.full((M, 2), np.nan)
    if xy is not None:
        centroid, centroid_views = _detections_centroid(K, R, centers, xy, mask)
    target, target_name = (
        (centroid, "the detections' centroid") if centroid is not None else (None, "")
    )
    if target is None and axes_converge:
        target, target_name = axes_point, "the point the optical axes converge to"
    if target is not None:
        to_target = target[None, :] - centers
        norm = np.linalg.norm(to_target, axis=-1)
        cos = np.einsum("mi,mi->m", dirs, to_target) / np.where(norm > 0, norm, 1.0)
        target_angle = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
        h = np.einsum("mij,mj->mi", K, np.einsum("mij,j->mi", R, target) + t)
        front = _in_front(R, t, target)
        target_pixel = np.where(
            front[:, None], h[:, :2] / np.where(front, h[:, 2], 1.0)[:, None], np.nan
        )
        if centroid is not None:
            angle, pixel = target_angle, target_pixel
        for m in range(M):
            if target_angle[m] > 90.0:
                warnings.append(
                    f"view {names[m]}: its optical axis points away from {target_name} "
                    f"{_vec(target)} (angle {target_angle[m]:.0f}° > 90°)"
                )
                pointing += 1
            elif sizes is not None and not _inside(target_pixel[m], sizes[m]):
                w, hgt = sizes[m]
                warnings.append(
                    f"view {names[m]}: {target_name} {_vec(target)} projects to "
                    f"{_vec(target_pixel[m], '.0f')} px, outside its {w:g}×{hgt:g} image"
                )
                pointing += 1

    if target is not None and M >= 2:
        warnings += _short_baselines(centers, target, target_name, dist_cc, names)

    return RigDescription(
        names=names,
        centers=centers,
        view_dirs=dirs,
        focal_px=focal,
        principal_px=principal,
        image_size=sizes,
        baseline_min=b_min,
        baseline_median=b_med,
        baseline_max=b_max,
        closest_pair=closest,
        axes_point=axes_point,
        axes_point_in_front=axes_front,
        centroid=centroid,
        centroid_views=centroid_views,
        centroid_angle_deg=angle,
        centroid_pixel=pixel,
        warnings=warnings,
    ), pointing


def _short_baselines(centers, target, target_name, dist_cc, names) -> list[str]:
    """One warning per pair of distinct cameras whose baseline subtends less than
    the default ``Config.min_parallax_deg`` at ``target``: a point they alone see cannot pass the
    validity gate (and is poorly determined)."""
    limit = DEFAULT_MIN_PARALLAX_DEG
    to_target = target[None, :] - centers
    norm = np.linalg.norm(to_target, axis=-1)
    u = to_target / np.where(norm > 0, norm, 1.0)[:, None]
    out = []
    M = centers.shape[0]
    tol = 1e-6 * max(float(np.abs(centers).max()), float(dist_cc.max()), 1e-12)
    for i, j in zip(*np.triu_indices(M, k=1)):
        if dist_cc[i, j] <= tol:
            continue  # already reported as the same centre
        angle = float(np.degrees(np.arccos(np.clip(abs(u[i] @ u[j]), 0.0, 1.0))))
        if angle < limit:
            out.append(
                f"views {names[i]} and {names[j]} are only {dist_cc[i, j]:.3g} apart: seen from "
                f"{target_name} {_vec(target)} their baseline spans {angle:.3g}° (< {limit:g}°, "
                f"Config.min_parallax_deg), so points seen only by these two views are not triangulated"
            )
    return out


def host_views(rig: Rig, names, what: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """One unbatched rig as float64 host ``K, R (M, 3, 3)``, ``t (M, 3)`` and ``M`` view
    names (default ``"0" … "M-1"``); ``what`` names the caller in errors."""
    K, R, t = (np.asarray(a, dtype=np.float64) for a in (rig.K, rig.R, rig.t))
    if K.ndim != 3 or K.shape[1:] != (3, 3):
        raise ValueError(f"{what} needs one unbatched rig, K of shape (M, 3, 3); got {K.shape}")
    M = K.shape[0]
    names = [str(m) for m in range(M)] if names is None else [str(n) for n in names]
    if len(names) != M:
        raise ValueError(f"names must hold M={M} entries; got {len(names)}")
    return K, R, t, names


def image_sizes(image_size, M: int) -> np.ndarray | None:
    """``(M, 2)`` float image sizes from None, ``(w, h)`` or ``(M, 2)``."""
    if image_size is None:
        return None
    sizes = np.asarray(image_size, dtype=np.float64)
    if sizes.shape == (2,):
        sizes = np.broadcast_to(sizes, (M, 2))
    if sizes.shape != (M, 2):
        raise ValueError(
            f"image_size must be (width, height) or shape (M, 2) with M={M}; got {sizes.shape}"
        )
    return sizes


def _nearest_point(origins: np.ndarray, dirs: np.ndarray) -> np.ndarray | None:
    """Least-squares point nearest to the lines ``origins (L, 3) + s dirs (L, 3)`` (unit dirs):
    ``Σ (I − d dᵀ) X = Σ (I − d dᵀ) o``. None when the lines are (nearly) parallel."""
    proj = np.eye(3)[None] - np.einsum("li,lj->lij", dirs, dirs)  # (L, 3, 3)
    A = proj.sum(axis=0)
    b = np.einsum("lij,lj->i", proj, origins)
    eig = np.linalg.eigvalsh(A)
    if eig[0] <= 1e-9 * max(eig[-1], 1e-300):
        return None
    return np.linalg.solve(A, b)


def _in_front(R: np.ndarray, t: np.ndarray, X: np.ndarray) -> np.ndarray:
    """``(M,)`` bool, ``(R X + t)_z > 0``."""
    return R[:, 2, :] @ X + t[:, 2] > 0


def _inside(pixel: np.ndarray, size: np.ndarray) -> bool:
    return bool(np.all(np.isfinite(pixel)) and 0 <= pixel[0] < size[0] and 0 <= pixel[1] < size[1])


def _detections_centroid(K, R, centers, xy, mask):
    """Least-squares point of the rays through every view's mean (undistorted) detection."""
    M = K.shape[0]
    xy = np.asarray(xy, dtype=np.float64)
    if xy.ndim != 3 or xy.shape[0] != M or xy.shape[2] != 2:
        raise ValueError(f"xy must have shape (M, P, 2) with M={M} from the rig; got {xy.shape}")
    mask = np.ones(xy.shape[:2], bool) if mask is None else np.asarray(mask, dtype=bool)
    if mask.shape != xy.shape[:2]:
        raise ValueError(f"mask must have shape {xy.shape[:2]} (M, P) like xy; got {mask.shape}")
    count = mask.sum(axis=1)
    views = count > 0
    if views.sum() < 2:
        return None, views
    mean_px = np.where(mask[..., None], xy, 0.0).sum(axis=1)[views] / count[views, None]  # (V, 2)
    ray_cam = np.einsum(
        "vij,vj->vi",
        np.linalg.inv(K[views]),
        np.concatenate([mean_px, np.ones_like(mean_px[:, :1])], -1),
    )
    # The pixel fixes the ray only up to sign (K[2,2] may be -1): take the half in front.
    ray_cam = ray_cam * np.sign(ray_cam[:, 2:3])
    ray_world = np.einsum("vji,vj->vi", R[views], ray_cam)
    ray_world /= np.linalg.norm(ray_world, axis=-1, keepdims=True)
    return _nearest_point(centers[views], ray_world), views


def _vec(v, fmt: str = ".4g") -> str:
    return "(" + ", ".join(format(float(x), fmt) for x in v) + ")"


def _format(d: RigDescription) -> str:
    M = len(d.names)
    lines = [
        f"Rig: {M} view{'s' if M != 1 else ''} (world→camera X_cam = R X + t; lengths in scene units)"
    ]
    width = max(4, *(len(n) for n in d.names))
    header = f"  {'view':<{width}}  {'centre':>28}  {'viewing direction':>24}  {'fx, fy (px)':>17}  {'cx, cy (px)':>17}"
    if d.image_size is not None:
        header += f"  {'image (px)':>11}"
    lines.append(header)
    for m in range(M):
        c = ", ".join(f"{x:8.4g}" for x in d.centers[m])
        v = ", ".join(f"{x:+6.3f}" for x in d.view_dirs[m])
        row = (
            f"  {d.names[m]:<{width}}  ({c})  ({v})  {d.focal_px[m, 0]:8.1f},{d.focal_px[m, 1]:8.1f}"
            f"  {d.principal_px[m, 0]:8.1f},{d.principal_px[m, 1]:8.1f}"
        )
        if d.image_size is not None:
            row += f"  {d.image_size[m, 0]:>5g}×{d.image_size[m, 1]:<5g}"
        lines.append(row)
    if d.closest_pair is not None:
        i, j = d.closest_pair
        lines.append(
            f"Baselines: min {d.baseline_min:.4g} (views {d.names[i]}–{d.names[j]}), "
            f"median {d.baseline_median:.4g}, max {d.baseline_max:.4g}"
        )
    if d.axes_point is not None:
        lines.append(
            f"Point nearest to all optical axes: {_vec(d.axes_point)}, in front of "
            f"{int(d.axes_point_in_front.sum())} of {M} cameras"
        )
    elif M >= 2:
        lines.append("Optical axes: all parallel, no point nearest to them")
    if d.centroid is not None:
        used = int(d.centroid_views.sum())
        lines.append(
            f"Detections' centroid (rays through the mean detection of {used} views): {_vec(d.centroid)}; "
            f"angle to the optical axes {np.nanmin(d.centroid_angle_deg):.1f}°–{np.nanmax(d.centroid_angle_deg):.1f}°"
        )
    if d.warnings:
        lines.append(f"WARNINGS ({len(d.warnings)}):")
        lines.extend(f"  - {w}" for w in d.warnings)
    else:
        lines.append("No warnings.")
    return "\n".join(lines)
