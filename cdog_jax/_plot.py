"""Figure of one association result: the detections of every view coloured by group, and
the triangulated points in 3D beside the cameras.

Host-side only: every array is converted to NumPy first, nothing here is traced. The figure
is a plain :class:`matplotlib.figure.Figure` bound to the Agg canvas, so it renders headless
and never touches pyplot's global state or the user's selected backend.
"""

from __future__ import annotations

import math
import os

import numpy as np

from ._result import Association
from .geometry._camera import Rig
from .io._atomic import atomic_savefig
from .synthetic._rig import IMAGE_SIZE

# Qualitative palette: tab20 without its two greys (grey is kept for unassigned
# detections), crossed with a few marker shapes, so 18 × 4 = 72 groups look distinct.
_TAB20_NO_GREY = tuple(i for i in range(20) if i not in (14, 15))
_MARKERS = ("o", "s", "^", "D")
_UNASSIGNED_COLOR = "0.55"
_CAMERA_COLOR = "0.2"


def group_style(g: int) -> tuple[tuple[float, float, float, float], str]:
    """Colour (RGBA) and marker of group ``g``: cycles over 18 colours, then over 4 markers."""
    from matplotlib import colormaps

    n = len(_TAB20_NO_GREY)
    color = colormaps["tab20"](_TAB20_NO_GREY[g % n])
    return color, _MARKERS[(g // n) % len(_MARKERS)]


def _scatter_groups(ax, pts, gids, **kw) -> None:
    """Scatter ``pts (n, 2 or 3)`` of groups ``gids (n,)`` in their styles, one call per marker."""
    kinds = (gids // len(_TAB20_NO_GREY)) % len(_MARKERS)
    for k, marker in enumerate(_MARKERS):
        pick = kinds == k
        if pick.any():
            colors = [group_style(int(g))[0] for g in gids[pick]]
            ax.scatter(*pts[pick].T, c=colors, marker=marker, edgecolors="0.15", linewidths=0.4, **kw)


def plot_association(
    rig: Rig,
    xy,
    mask,
    result: Association,
    *,
    points3d_gt=None,
    image_size: tuple[int, int] = IMAGE_SIZE,
    title: str | None = None,
    path: str | os.PathLike | None = None,
):
    """Draw one scene's association: a panel per view and a 3D panel.

    Args:
        rig: the ``M`` cameras (``rig.centers`` and ``rig.view_dirs`` are drawn in 3D).
        xy: ``(M, P, 2)`` detections (pixels, image y axis pointing down).
        mask: ``(M, P)`` bool, slot holds a detection; padded slots are not drawn.
        result: the :class:`Association` of this scene (unbatched).
        points3d_gt: optional ``(I, 3)`` ground-truth points (scene units), drawn hollow black.
        image_size: ``(width, height)`` of every image in pixels.
        title: optional extra line for the figure title (e.g. the scene's metrics).
        path: if given, the figure is also saved there (format from the suffix).

    Returns:
        A :class:`matplotlib.figure.Figure` (Agg canvas).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.patches import Rectangle

    xy = np.asarray(xy, dtype=np.float64)
    mask = np.asarray(mask, dtype=bool)
    labels = np.asarray(result.labels)
    valid = np.asarray(result.valid, dtype=bool)
    M = mask.shape[0]
    if xy.ndim != 3 or xy.shape[2] != 2 or mask.shape != xy.shape[:2]:
        raise ValueError(f"xy must have shape (M, P, 2) and mask (M, P); got {xy.shape} and {mask.shape}")
    if labels.shape != mask.shape or valid.ndim != 1:
        raise ValueError(
            f"result must be one unbatched scene with labels of shape {mask.shape}; got {labels.shape}"
        )
    if np.asarray(rig.K).shape != (M, 3, 3):
        raise ValueError(f"rig.K must have shape (M, 3, 3) with M={M}; got {np.asarray(rig.K).shape}")
    G = valid.shape[0]
    points3d = np.asarray(result.points3d, dtype=np.float64)
    n_views = np.asarray(result.n_views)
    # A detection belongs to a group when its label points at a valid group.
    in_range = (labels >= 0) & (labels < G)
    assigned = mask & in_range & (valid[np.where(in_range, labels, 0)] if G else False)
    unassigned = mask & ~assigned
    group_ids = np.flatnonzero(valid)
    width, height = image_size

    # Layout: views in a grid of at most 5 columns, the 3D panel to the right of them
    # spanning all rows, about 2.5 view panels wide.
    ncols = min(M, 5)
    nrows = math.ceil(M / ncols)
    fig = Figure(figsize=(3.2 * ncols + 7.0, 2.35 * nrows + 1.5), dpi=110)
    FigureCanvasAgg(fig)
    gs = fig.add_gridspec(nrows, ncols + 1, width_ratios=[1.0] * ncols + [2.6], left=0.035, right=0.995,
                          top=1 - 1.05 / fig.get_figheight(), bottom=0.7 / fig.get_figheight(),
                          wspace=0.25, hspace=0.3)
    margin_x, margin_y = 0.05 * width, 0.05 * height

    for m in range(M):
        r, c = divmod(m, ncols)
        ax = fig.add_subplot(gs[r, c])
        ax.add_patch(Rectangle((0, 0), width, height, facecolor="#f5f5f5", edgecolor="0.35", lw=0.8, zorder=0))
        _scatter_groups(ax, xy[m][assigned[m]], labels[m][assigned[m]], s=22, zorder=3)
        if unassigned[m].any():
            pts = xy[m][unassigned[m]]
            ax.scatter(pts[:, 0], pts[:, 1], s=16, c=_UNASSIGNED_COLOR, marker="x", linewidths=0.9, zorder=2)
        ax.set_xlim(-margin_x, width + margin_x)
        ax.set_ylim(height + margin_y, -margin_y)  # image y axis points down
        ax.set_aspect("equal")
        ax.set_xticks(np.linspace(0, width, 3))
        ax.set_yticks(np.linspace(0, height, 3))
        ax.tick_params(labelsize=7, length=2, pad=1.5)
        if r == nrows - 1 or m + ncols >= M:
            ax.set_xlabel("x (px)", fontsize=7, labelpad=1)
        if c == 0:
            ax.set_ylabel("y (px)", fontsize=7, labelpad=1)
        n_det, n_un = int(mask[m].sum()), int(unassigned[m].sum())
        ax.set_title(f"view {m}", fontsize=10, fontweight="bold", loc="left", pad=3)
        ax.set_title(f"{n_det} det., {n_un} unassigned", fontsize=7, loc="right", pad=3, color="0.35")

    ax3 = fig.add_subplot(gs[:, ncols], projection="3d")
    centers = np.asarray(rig.centers, dtype=np.float64)
    dirs = np.asarray(rig.view_dirs, dtype=np.float64)
    cloud = [centers]
    if group_ids.size:
        cloud.append(points3d[group_ids])
        _scatter_groups(ax3, points3d[group_ids], group_ids, s=20, depthshade=False)
    if points3d_gt is not None:
        gt = np.asarray(points3d_gt, dtype=np.float64).reshape(-1, 3)
        cloud.append(gt)
        ax3.scatter(gt[:, 0], gt[:, 1], gt[:, 2], s=42, facecolors="none", edgecolors="k",
                    linewidths=0.7, marker="o", depthshade=False)
    extent = np.concatenate(cloud)
    axis_len = 0.12 * float(np.max(np.ptp(extent, axis=0))) if extent.size else 1.0
    ax3.scatter(centers[:, 0], centers[:, 1], centers[:, 2], s=55, c=_CAMERA_COLOR, marker="^", depthshade=False)
    for m in range(M):
        tip = centers[m] + axis_len * dirs[m]
        ax3.plot(*np.stack([centers[m], tip]).T, color=_CAMERA_COLOR, lw=0.9)
        ax3.text(*(centers[m] + 0.35 * axis_len * np.array([0.0, 0.0, 1.0])), str(m), fontsize=8, color=_CAMERA_COLOR)
    lo, hi = extent.min(axis=0), extent.max(axis=0)
    ax3.set_box_aspect(tuple(np.maximum(hi - lo, 1e-3 * max(float(np.max(hi - lo)), 1e-9))), zoom=1.2)
    ax3.set_xlabel("X", fontsize=8, labelpad=-4)
    ax3.set_ylabel("Y", fontsize=8, labelpad=-4)
    ax3.set_zlabel("Z", fontsize=8, labelpad=-6)
    ax3.tick_params(labelsize=6, pad=-1)
    ax3.view_init(elev=28, azim=-58)
    ax3.set_title("3D: triangulated groups and cameras", fontsize=10, fontweight="bold", y=1.04)

    n_det, n_un = int(mask.sum()), int(unassigned.sum())
    if group_ids.size:
        nv = n_views[group_ids]
        span = f"{nv.min()}–{nv.max()} views each" if nv.min() != nv.max() else f"{nv.min()} views each"
        groups_txt = f"{group_ids.size} groups ({span})"
    else:
        groups_txt = "no groups"
    line = (
        f"C-DOG association: {M} views, {n_det} detections, {groups_txt}, {n_un} unassigned"
        f"   ·   σ = {float(np.asarray(result.sigma_px)):.2f} px, τ = {float(np.asarray(result.tau_px)):.2f} px"
    )
    fig.suptitle(line if title is None else f"{line}\n{title}", fontsize=12, y=1 - 0.12 / fig.get_figheight(),
                 va="top", linespacing=1.5)

    def proxy(marker, **kw):
        return Line2D([], [], linestyle="none", marker=marker, **kw)

    handles = [
        proxy("o", markerfacecolor=group_style(0)[0], markeredgecolor="0.15", markersize=6),
        proxy("x", color=_UNASSIGNED_COLOR, markersize=6, markeredgewidth=1.2),
        proxy("^", color=_CAMERA_COLOR, markersize=7),
    ]
    names = [
        "group member / triangulated point (colour + marker = group id)",
        "unassigned detection",
        "camera centre + optical axis (label = view)",
    ]
    if points3d_gt is not None:
        handles.insert(2, proxy("o", markerfacecolor="none", markeredgecolor="k", markersize=7))
        names.insert(2, "ground-truth 3D point")
    fig.legend(handles, names, loc="lower center", ncol=len(handles), fontsize=9, frameon=False,
               bbox_to_anchor=(0.5, 0.0), handletextpad=0.3, columnspacing=2.0)

    if path is not None:
        atomic_savefig(fig, path)
    return fig
