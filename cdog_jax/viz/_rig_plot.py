"""A 3D picture of a rig: camera centres, small view frusta, labels and optional points.

Host-side only (NumPy), and headless: without ``ax`` the figure is a plain
:class:`matplotlib.figure.Figure` bound to the Agg canvas, so pyplot's global state and the
user's backend are never touched. Save it with ``ax.figure.savefig(path)``.
"""

from __future__ import annotations

import numpy as np

from .._expect import expect_args
from ..geometry._camera import Rig
from ..geometry._describe import host_views, image_sizes
from ._plot import group_style

_CAMERA_COLOR = "0.2"
_POINT_COLOR = "tab:blue"


def _frustum_corners(
    K: np.ndarray, R: np.ndarray, t: np.ndarray, size: np.ndarray, depth: float
) -> np.ndarray:
    """World coordinates ``(M, 4, 3)`` of the image corners ``(0,0), (w,0), (w,h), (0,h)``
    of every view pushed out to camera depth ``depth`` (scene units); ``size (M, 2)``."""
    w, h = size[:, 0], size[:, 1]
    zero = np.zeros_like(w)
    px = np.stack(
        [
            np.stack([zero, zero], -1),
            np.stack([w, zero], -1),
            np.stack([w, h], -1),
            np.stack([zero, h], -1),
        ],
        1,
    )
    ray = np.einsum(
        "mij,mcj->mci", np.linalg.inv(K), np.concatenate([px, np.ones_like(px[..., :1])], -1)
    )  # (M, 4, 3)
    # Scale each ray to depth `depth` in front (K[2,2] may be -1, so the sign comes from z).
    X_cam = ray * (depth / ray[..., 2:3])
    return np.einsum("mji,mcj->mci", R, X_cam - t[:, None, :])


def plot_rig(rig: Rig, *, ax=None, points=None, names=None, image_size=None, frustum_depth=None):
    """Draw the cameras of one rig in 3D, in world coordinates with equal aspect.

    Args:
        rig: one unbatched rig of ``M`` views.
        ax: a matplotlib 3D axes to draw into; default: a new Agg figure.
        points: optional ``(N, 3)`` world points (scene units), drawn as dots; non-finite
            rows are skipped.
        names: optional ``M`` view labels (default ``"0" … "M-1"``).
        image_size: ``(width, height)`` in pixels, shared, or ``(M, 2)`` per view, for the
            frusta; default: twice the principal point of ``K / K[2,2]``.
        frustum_depth: depth of the frusta (scene units); default 12 % of the scene extent.

    Returns:
        The matplotlib ``Axes3D``; each frustum is one line whose data starts at the
        camera centre (``ax.lines[m]`` for view ``m``).
    """
    expect_args("plot_rig", rig=(rig, Rig))
    K, R, t, names = host_views(rig, names, "plot_rig")
    M = K.shape[0]
    size = image_sizes(image_size, M)
    if size is None:
        Kn = K / K[:, 2:3, 2:3]
        size = np.abs(2.0 * Kn[:, :2, 2])
        size = np.where(
            size > 0, size, np.abs(Kn[:, [0, 1], [0, 1]])
        )  # principal point at 0: use f
    pts = (
        np.zeros((0, 3)) if points is None else np.asarray(points, dtype=np.float64).reshape(-1, 3)
    )
    pts = pts[np.isfinite(pts).all(axis=1)]

    centers = -np.einsum("mji,mj->mi", R, t)
    cloud = np.concatenate([centers, pts])
    extent = float(np.max(np.ptp(cloud, axis=0))) if len(cloud) > 1 else 0.0
    if frustum_depth is None:
        frustum_depth = 0.12 * extent if extent > 0 else 1.0
    corners = _frustum_corners(K, R, t, size, float(frustum_depth))  # (M, 4, 3)

    if ax is None:
        # matplotlib loads with the first figure: importing the package stays quick
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        fig = Figure(figsize=(7.0, 6.0), dpi=100)
        FigureCanvasAgg(fig)
        ax = fig.add_subplot(projection="3d")

    for m in range(M):
        c0, c1, c2, c3 = corners[m]
        C = centers[m]
        # One polyline through all 8 edges: the image rectangle and the 4 rays to its corners.
        path = np.stack([C, c0, c1, c2, c3, c0, C, c1, C, c2, C, c3])
        ax.plot(*path.T, color=_CAMERA_COLOR, lw=0.9)
    for m in range(M):
        # Mark the image's top edge (y = 0) so that the roll of each camera can be read.
        top = 0.5 * (corners[m, 0] + corners[m, 1])
        ax.plot(
            *np.stack([corners[m, 0], top + 0.25 * (top - corners[m, 3]), corners[m, 1]]).T,
            color="tab:red",
            lw=0.9,
        )
    ax.scatter(
        *centers.T, s=30, c=_CAMERA_COLOR, marker="o", depthshade=False, label="camera centre"
    )
    for m in range(M):
        ax.text(*centers[m], f" {names[m]}", fontsize=8, color=_CAMERA_COLOR)
    if len(pts):
        ax.scatter(*pts.T, s=8, c=_POINT_COLOR, depthshade=False, label="points")

    # Equal aspect: a cube of limits around everything drawn, and a cubic box.
    everything = np.concatenate([cloud, corners.reshape(-1, 3)])
    lo, hi = everything.min(axis=0), everything.max(axis=0)
    mid, half = 0.5 * (lo + hi), 0.5 * max(float(np.max(hi - lo)), 1e-9) * 1.05
    ax.set_xlim(mid[0] - half, mid[0] + half)
    ax.set_ylim(mid[1] - half, mid[1] + half)
    ax.set_zlim(mid[2] - half, mid[2] + half)
    ax.set_box_aspect((1.0, 1.0, 1.0))
    ax.set_xlabel("X (scene units)")
    ax.set_ylabel("Y (scene units)")
    ax.set_zlabel("Z (scene units)")
    ax.set_title(
        f"Rig: {M} cameras (frusta to depth {frustum_depth:.3g}; red tick = image top)", fontsize=10
    )
    return ax


def plot_rays(rig: Rig, xy, mask, *, result=None, depth=None, ax=None, names=None, image_size=None):
    """Draw the rig (as :func:`plot_rig`) and the ray from every camera centre through each
    of its detections: the rays of one group should meet at its 3D point.

    Args:
        rig: one unbatched rig of ``M`` views (distortion-free pixels: undistort first).
        xy: ``(M, P, 2)`` detections (pixels).
        mask: ``(M, P)`` bool; only valid detections get a ray.
        result: optional unbatched :class:`cdog_jax.Association`: rays are coloured by
            group (unassigned ones thin and grey), each group's ray stops just past its 3D
            point, and the points are drawn.
        depth: length of the rays without a group point (scene units); default: 1.2 × the
            largest distance from a camera to a group point, or the rig's width.
        ax, names, image_size: as for :func:`plot_rig`.

    Returns:
        The matplotlib ``Axes3D``. The rays are ``ax.lines[-n:]``, ``n`` the number of
        valid detections, in view-major slot order, each starting at its camera centre.
    """
    expect_args("plot_rays", rig=(rig, Rig))
    K, R, t, _ = host_views(rig, names, "plot_rays")
    xy = np.asarray(xy, dtype=np.float64)
    mask = np.asarray(mask, dtype=bool)
    M = K.shape[0]
    if xy.ndim != 3 or xy.shape[0] != M or xy.shape[2] != 2 or mask.shape != xy.shape[:2]:
        raise ValueError(
            f"plot_rays: xy must be (M, P, 2) and mask (M, P) with M={M}; got {xy.shape} and {mask.shape}"
        )
    centers = -np.einsum("mji,mj->mi", R, t)
    labels = np.full(mask.shape, -1)
    points = np.zeros((0, 3))
    if result is not None:
        labels = np.asarray(result.labels)
        if labels.shape != mask.shape:
            raise ValueError(
                f"plot_rays: result must be one unbatched scene; labels {labels.shape}, mask {mask.shape}"
            )
        valid = np.asarray(result.valid, dtype=bool)
        labels = np.where((labels >= 0) & valid[np.maximum(labels, 0)], labels, -1)
        points = np.asarray(result.points3d, dtype=np.float64)
    used = np.unique(labels[labels >= 0])
    if depth is None:
        reach = (
            np.linalg.norm(points[used][None, :, :] - centers[:, None, :], axis=-1)
            if used.size
            else np.zeros(0)
        )
        depth = (
            1.2 * float(reach.max())
            if reach.size
            else float(np.max(np.ptp(centers, axis=0))) or 1.0
        )
    ax = plot_rig(
        rig, ax=ax, points=points[used] if used.size else None, names=names, image_size=image_size
    )

    pixels = np.concatenate([xy, np.ones_like(xy[..., :1])], axis=-1)
    ray = np.einsum("mij,mpj->mpi", np.linalg.inv(K), pixels)
    ray *= np.sign(ray[..., 2:3]) + (ray[..., 2:3] == 0)  # in front: positive camera depth
    world = np.einsum("mji,mpj->mpi", R, ray)
    world /= np.linalg.norm(world, axis=-1, keepdims=True)
    for m, p in zip(*np.nonzero(mask)):
        g = int(labels[m, p])
        length = depth
        if g >= 0:
            length = 1.08 * float(
                np.dot(points[g] - centers[m], world[m, p])
            )  # just past the point
            color, lw, alpha = group_style(g)[0], 0.9, 0.9
        else:
            color, lw, alpha = "0.6", 0.5, 0.6
        end = centers[m] + max(length, 1e-9) * world[m, p]
        ax.plot(*np.stack([centers[m], end]).T, color=color, lw=lw, alpha=alpha)
    n = int(mask.sum())
    assigned = int((labels[mask] >= 0).sum())
    ax.set_title(
        f"Rays through {n} detections ({assigned} in {used.size} groups, coloured; others grey)",
        fontsize=10,
    )
    return ax
