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

from .._result import Association
from ..geometry._camera import Rig
from ..io._atomic import atomic_savefig
from ..synthetic._rig import IMAGE_SIZE

# Every group gets its own colour: hues stepped by the golden ratio (neighbouring ids far
# apart on the colour wheel, no hue ever repeats exactly), two lightness levels, and four
# marker shapes on top, so a group can be followed across views however many there are.
# Grey is kept for unassigned detections; red rings mark wrong groups.
_GOLDEN = 0.6180339887498949
_MARKERS = ("o", "s", "^", "D")
_UNASSIGNED_COLOR = "0.55"
_CAMERA_COLOR = "0.2"
_WRONG_COLOR = "#d40000"
_MAX_NUMBERED_GROUPS = 60  # above this, group numbers next to detections are left out


def group_style(g: int) -> tuple[tuple[float, float, float, float], str]:
    """Colour (RGBA) and marker of group ``g``; no two groups below a few hundred share both."""
    # matplotlib loads with the first figure: importing the package stays quick
    from matplotlib.colors import hsv_to_rgb

    hue = (0.07 + g * _GOLDEN) % 1.0
    sat, val = ((0.85, 0.92), (0.55, 0.72))[(g // len(_MARKERS)) % 2]
    return (*hsv_to_rgb((hue, sat, val)), 1.0), _MARKERS[g % len(_MARKERS)]


def _scatter_groups(ax, pts, gids, **kw) -> None:
    """Scatter ``pts (n, 2 or 3)`` of groups ``gids (n,)`` in their styles, one call per marker."""
    kinds = gids % len(_MARKERS)
    for k, marker in enumerate(_MARKERS):
        pick = kinds == k
        if pick.any():
            colors = [group_style(int(g))[0] for g in gids[pick]]
            ax.scatter(
                *pts[pick].T, c=colors, marker=marker, edgecolors="0.15", linewidths=0.5, **kw
            )


def wrong_groups(groups, valid, instance) -> np.ndarray:
    """``(G,)`` bool: the valid groups whose members are not all detections of one true
    point (ground truth ``instance (M, P)``, ``-1`` for clutter, which is always wrong)."""
    groups = np.asarray(groups)
    valid = np.asarray(valid, dtype=bool)
    instance = np.asarray(instance)
    member = groups >= 0
    ids = np.where(member, instance[np.arange(groups.shape[1])[None, :], np.maximum(groups, 0)], -2)
    first = np.max(np.where(member, ids, -2), axis=1)
    mixed = np.any(member & (ids != first[:, None]), axis=1) | np.any(member & (ids < 0), axis=1)
    return valid & mixed


def _camera_label_clusters(centers: np.ndarray, radius: float) -> list[list[int]]:
    """Views whose centres lie within ``radius`` of each other, chained: one label each."""
    clusters: list[list[int]] = []
    for m in range(len(centers)):
        near = [
            c for c in clusters if np.min(np.linalg.norm(centers[c] - centers[m], axis=1)) < radius
        ]
        merged = [m] + [v for c in near for v in c]
        clusters = [c for c in clusters if c not in near] + [sorted(merged)]
    return sorted(clusters)


def plot_association(
    rig: Rig,
    xy,
    mask,
    result: Association,
    *,
    points3d_gt=None,
    instance=None,
    image_size: tuple[int, int] = IMAGE_SIZE,
    title: str | None = None,
    path: str | os.PathLike | None = None,
):
    """Draw one scene's association: a panel per view and a 3D panel.

    Every group has its own colour and marker in every view and in 3D, and its number next
    to each of its detections (up to 60 groups), so that it can be followed across views.

    Args:
        rig: the ``M`` cameras (``rig.centers`` and ``rig.view_dirs`` are drawn in 3D).
        xy: ``(M, P, 2)`` detections (pixels, image y axis pointing down).
        mask: ``(M, P)`` bool, slot holds a detection; padded slots are not drawn.
        result: the :class:`Association` of this scene (unbatched).
        points3d_gt: optional ``(I, 3)`` ground-truth points (scene units), drawn hollow black.
        instance: optional ``(M, P)`` int ground-truth point of every detection (``-1``:
            clutter); groups whose members are not all one point are ringed in red.
        image_size: ``(width, height)`` of every image in pixels.
        title: optional extra line for the figure title (e.g. the scene's metrics).
        path: if given, the figure is also saved there (format from the suffix).

    Returns:
        A :class:`matplotlib.figure.Figure` (Agg canvas): ``M`` view axes, then the 3D axes.
    """
    # matplotlib loads with the first figure: importing the package stays quick
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.legend_handler import HandlerTuple
    from matplotlib.lines import Line2D
    from matplotlib.patches import Rectangle

    xy = np.asarray(xy, dtype=np.float64)
    mask = np.asarray(mask, dtype=bool)
    labels = np.asarray(result.labels)
    valid = np.asarray(result.valid, dtype=bool)
    M = mask.shape[0]
    if xy.ndim != 3 or xy.shape[2] != 2 or mask.shape != xy.shape[:2]:
        raise ValueError(
            f"xy must have shape (M, P, 2) and mask (M, P); got {xy.shape} and {mask.shape}"
        )
    if labels.shape != mask.shape or valid.ndim != 1:
        raise ValueError(
            f"result must be one unbatched scene with labels of shape {mask.shape}; got {labels.shape}"
        )
    if np.asarray(rig.K).shape != (M, 3, 3):
        raise ValueError(
            f"rig.K must have shape (M, 3, 3) with M={M}; got {np.asarray(rig.K).shape}"
        )
    if instance is not None and np.shape(instance) != mask.shape:
        raise ValueError(
            f"instance must have the shape of mask {mask.shape}; got {np.shape(instance)}"
        )
    G = valid.shape[0]
    points3d = np.asarray(result.points3d, dtype=np.float64)
    n_views = np.asarray(result.n_views)
    # A detection belongs to a group when its label points at a valid group.
    in_range = (labels >= 0) & (labels < G)
    assigned = mask & in_range & (valid[np.where(in_range, labels, 0)] if G else False)
    unassigned = mask & ~assigned
    group_ids = np.flatnonzero(valid)
    wrong = np.zeros(G, bool) if instance is None else wrong_groups(result.groups, valid, instance)
    wrong_det = assigned & wrong[np.where(in_range, labels, 0)] if G else np.zeros_like(mask)
    numbered = group_ids.size <= _MAX_NUMBERED_GROUPS
    width, height = image_size

    # Layout: the views in rows of at most 5, the 3D panel below them on the left, the
    # legend and the summary beside it; about 1500 px wide at 100 dpi.
    ncols = min(M, 5)
    nrows = math.ceil(M / ncols)
    panel_w = 3.0
    panel_h = panel_w * height / width + 0.55
    fig_w = panel_w * max(ncols, 4) + 0.6
    fig_h = panel_h * nrows + 5.6 + 1.0
    fig = Figure(figsize=(fig_w, fig_h), dpi=100)
    FigureCanvasAgg(fig)
    top = 1 - 1.0 / fig_h
    views_bottom = top - panel_h * nrows / fig_h
    gs = fig.add_gridspec(
        nrows,
        ncols,
        left=0.05,
        right=0.99,
        top=top,
        bottom=views_bottom + 0.35 / fig_h,
        wspace=0.18,
        hspace=0.3,
    )
    margin_x, margin_y = 0.04 * width, 0.04 * height

    for m in range(M):
        r, c = divmod(m, ncols)
        ax = fig.add_subplot(gs[r, c])
        ax.add_patch(
            Rectangle(
                (0, 0), width, height, facecolor="#f4f4f4", edgecolor="0.35", lw=0.8, zorder=0
            )
        )
        pts, gids = xy[m][assigned[m]], labels[m][assigned[m]]
        _scatter_groups(ax, pts, gids, s=34, zorder=3)
        if wrong_det[m].any():
            bad = xy[m][wrong_det[m]]
            ax.scatter(
                bad[:, 0],
                bad[:, 1],
                s=150,
                facecolors="none",
                edgecolors=_WRONG_COLOR,
                linewidths=1.6,
                zorder=4,
            )
        if numbered:
            for (x, y), g in zip(pts, gids):
                ax.annotate(
                    str(int(g)),
                    (x, y),
                    xytext=(3.5, 2.5),
                    textcoords="offset points",
                    fontsize=7.5,
                    color=group_style(int(g))[0],
                    fontweight="bold",
                    zorder=5,
                )
        if unassigned[m].any():
            pts = xy[m][unassigned[m]]
            ax.scatter(
                pts[:, 0],
                pts[:, 1],
                s=24,
                c=_UNASSIGNED_COLOR,
                marker="x",
                linewidths=1.1,
                zorder=2,
            )
        ax.set_xlim(-margin_x, width + margin_x)
        ax.set_ylim(height + margin_y, -margin_y)  # image y axis points down
        ax.set_aspect("equal")
        ax.set_xticks(np.linspace(0, width, 3))
        ax.set_yticks(np.linspace(0, height, 3))
        ax.tick_params(labelsize=9, length=2, pad=1.5)
        if c == 0:
            ax.set_ylabel("y (px)", fontsize=9, labelpad=1)
        n_det, n_un = int(mask[m].sum()), int(unassigned[m].sum())
        ax.set_title(f"view {m}", fontsize=12, fontweight="bold", loc="left", pad=3)
        ax.set_title(
            f"{n_det} det., {n_un} unassigned", fontsize=9, loc="right", pad=3, color="0.3"
        )

    ax3 = fig.add_axes(
        (0.02, 0.5 / fig_h, 0.56, (views_bottom * fig_h - 0.9) / fig_h), projection="3d"
    )
    centers, dirs = rig.centers_and_dirs_on_host()
    cloud = [centers]
    if group_ids.size:
        cloud.append(points3d[group_ids])
        _scatter_groups(ax3, points3d[group_ids], group_ids, s=30, depthshade=False)
        bad = group_ids[wrong[group_ids]]
        if bad.size:
            ax3.scatter(
                *points3d[bad].T,
                s=120,
                facecolors="none",
                edgecolors=_WRONG_COLOR,
                linewidths=1.5,
                depthshade=False,
            )
    if points3d_gt is not None:
        gt = np.asarray(points3d_gt, dtype=np.float64).reshape(-1, 3)
        cloud.append(gt)
        ax3.scatter(
            gt[:, 0],
            gt[:, 1],
            gt[:, 2],
            s=60,
            facecolors="none",
            edgecolors="k",
            linewidths=0.8,
            marker="o",
            depthshade=False,
        )
    extent = np.concatenate(cloud)
    span = float(np.max(np.ptp(extent, axis=0))) if extent.size else 1.0
    axis_len = 0.12 * span
    ax3.scatter(
        centers[:, 0],
        centers[:, 1],
        centers[:, 2],
        s=70,
        c=_CAMERA_COLOR,
        marker="^",
        depthshade=False,
    )
    for m in range(M):
        tip = centers[m] + axis_len * dirs[m]
        ax3.plot(*np.stack([centers[m], tip]).T, color=_CAMERA_COLOR, lw=1.0)
    lo, hi = extent.min(axis=0) - 0.04 * span, extent.max(axis=0) + 0.04 * span
    ax3.set_box_aspect(
        tuple(np.maximum(hi - lo, 1e-3 * max(float(np.max(hi - lo)), 1e-9))), zoom=1.1
    )
    ax3.view_init(elev=28, azim=-58)
    ax3.set_xlim(lo[0], hi[0])
    ax3.set_ylim(lo[1], hi[1])
    ax3.set_zlim(lo[2], hi[2])
    # Cameras that fall close together on screen share one label ("4, 5") instead of
    # overlapping; labels sit above their cameras, away from the axes pointing at the scene.
    from mpl_toolkits.mplot3d import proj3d

    screen = np.stack(proj3d.proj_transform(*centers.T, ax3.get_proj())[:2], axis=1)
    for views in _camera_label_clusters(screen, 0.06 * float(np.max(np.ptp(screen, axis=0)))):
        anchor = centers[views].mean(axis=0) + np.array([0.0, 0.0, 0.07 * span])
        ax3.text(
            *anchor,
            ", ".join(str(v) for v in views),
            fontsize=10,
            color=_CAMERA_COLOR,
            ha="center",
            fontweight="bold",
        )
    for setter, name in ((ax3.set_xlabel, "X"), (ax3.set_ylabel, "Y"), (ax3.set_zlabel, "Z")):
        setter(name, fontsize=10, labelpad=2)
    ax3.tick_params(labelsize=8, pad=0)
    ax3.set_title(
        "3D: triangulated groups and cameras (scene units)", fontsize=12, fontweight="bold"
    )

    n_det, n_un = int(mask.sum()), int(unassigned.sum())
    if group_ids.size:
        nv = n_views[group_ids]
        views_txt = (
            f"{nv.min()}–{nv.max()} views each"
            if nv.min() != nv.max()
            else f"{nv.min()} views each"
        )
        groups_txt = f"{group_ids.size} groups ({views_txt})"
    else:
        groups_txt = "no groups"
    if instance is not None:
        groups_txt += f", {int(wrong.sum())} wrong"
    line = (
        f"C-DOG association: {M} views, {n_det} detections, {groups_txt}, {n_un} unassigned"
        f"   ·   σ = {float(np.asarray(result.sigma_px)):.2f} px, τ = {float(np.asarray(result.tau_px)):.2f} px"
    )
    fig.suptitle(
        line if title is None else f"{line}\n{title}",
        fontsize=13,
        y=1 - 0.12 / fig_h,
        va="top",
        linespacing=1.5,
    )

    def proxy(marker, **kw):
        return Line2D([], [], linestyle="none", marker=marker, **kw)

    handles = [
        proxy(mk, markerfacecolor=group_style(g)[0], markeredgecolor="0.15", markersize=8)
        for g, mk in zip(range(4), _MARKERS)
    ]
    handles = [tuple(handles)]
    names = [
        "group member / its 3D point: one colour + marker per group"
        + (",\nits number beside each detection" if numbered else "")
    ]
    handles += [
        proxy("x", color=_UNASSIGNED_COLOR, markersize=8, markeredgewidth=1.3),
        proxy("^", color=_CAMERA_COLOR, markersize=9),
    ]
    names += ["unassigned detection", "camera centre + optical axis (label = view)"]
    if points3d_gt is not None:
        handles.append(proxy("o", markerfacecolor="none", markeredgecolor="k", markersize=9))
        names.append("ground-truth 3D point")
    if instance is not None:
        handles.append(
            proxy(
                "o",
                markerfacecolor="none",
                markeredgecolor=_WRONG_COLOR,
                markersize=12,
                markeredgewidth=1.6,
            )
        )
        names.append("wrong group: members of different true points")

    fig.legend(
        handles,
        names,
        loc="center left",
        bbox_to_anchor=(0.6, 0.5 * views_bottom),
        fontsize=11,
        frameon=False,
        handletextpad=0.6,
        labelspacing=1.1,
        handler_map={tuple: HandlerTuple(ndivide=None)},
    )

    if path is not None:
        atomic_savefig(fig, path)
    return fig
