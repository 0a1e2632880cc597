"""Figure of the first stage for one detection: its epipolar line in every other view, the
τ band around it, the detections inside the band (the candidates) and the nearest one (the
only one that can get an edge).

Host-side (NumPy) and headless: a plain :class:`matplotlib.figure.Figure` on the Agg canvas.
"""

from __future__ import annotations

import math
import os

import numpy as np

from .._expect import expect_args
from .._result import Association
from ..geometry._camera import Rig
from ..geometry._epipolar import fundamental_from_rig
from ..io._atomic import atomic_savefig
from ..synthetic._rig import IMAGE_SIZE
from ._plot import _UNASSIGNED_COLOR, _WRONG_COLOR, group_style

_LINE_COLOR = "#1f5fbf"
_CANDIDATE_COLOR = "#f08c00"


def _band_polygon(
    line: np.ndarray, offset: float, width: float, height: float, pad: float
) -> np.ndarray:
    """Corners ``(4, 2)`` of the strip ``|a x + b y + c| / ‖(a, b)‖ ≤ offset`` clipped to the
    image grown by ``pad`` px: parametrised along x when the line is closer to horizontal."""
    a, b, c = line
    n = math.hypot(a, b)
    shifts = (-offset * n, offset * n)
    if abs(b) >= abs(a):
        xs = np.array([-pad, width + pad])
        edges = [np.stack([xs, -(a * xs + c + s) / b], 1) for s in shifts]
    else:
        ys = np.array([-pad, height + pad])
        edges = [np.stack([-(b * ys + c + s) / a, ys], 1) for s in shifts]
    return np.concatenate([edges[0], edges[1][::-1]])


def plot_epipolar(
    rig: Rig,
    xy,
    mask,
    view: int,
    slot: int,
    *,
    tau_px: float | None = None,
    result: Association | None = None,
    instance=None,
    image_size: tuple[int, int] = IMAGE_SIZE,
    path: str | os.PathLike | None = None,
):
    """Draw the epipolar line of detection ``(view, slot)`` in every other view.

    Each panel shows the line, the band of half-width ``τ`` around it (and an inset zoomed
    on it when the nearest detection is within 3 τ), every detection of that view
    (candidates inside the band in orange), and the nearest detection to the line ringed: the edge of the first stage goes to that one only, if it lies inside the band
    (docs/ALGORITHM.md §1–2). With ``result`` the detection's group is drawn in its colour;
    with ``instance`` the true partner of the detection is marked.

    Args:
        rig: the ``M`` cameras (distortion-free pixels: undistort first if needed).
        xy: ``(M, P, 2)`` detections (pixels).
        mask: ``(M, P)`` bool.
        view, slot: the detection whose lines are drawn; ``mask[view, slot]`` must hold.
        tau_px: the gate τ (px); default ``result.tau_px``; one of the two is needed.
        result: optional unbatched :class:`Association` of the scene.
        instance: optional ``(M, P)`` ground-truth point of every detection (``-1``: clutter).
        image_size: ``(width, height)`` in pixels.
        path: if given, the figure is also saved there (format from the suffix).

    Returns:
        A :class:`matplotlib.figure.Figure`, one axes per view (``axes[view]`` the source).
    """
    # matplotlib loads with the first figure: importing the package stays quick
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.patches import Polygon, Rectangle

    expect_args("plot_epipolar", rig=(rig, Rig))
    xy = np.asarray(xy, dtype=np.float64)
    mask = np.asarray(mask, dtype=bool)
    M = rig.num_views
    if xy.shape[:1] != (M,) or xy.ndim != 3 or xy.shape[2] != 2 or mask.shape != xy.shape[:2]:
        raise ValueError(
            f"plot_epipolar: xy must be (M, P, 2) and mask (M, P) with M={M}; got {xy.shape} and {mask.shape}"
        )
    if not (0 <= view < M and 0 <= slot < mask.shape[1]) or not mask[view, slot]:
        raise ValueError(
            f"plot_epipolar: (view, slot) = ({view}, {slot}) is not a detection of this scene"
        )
    if tau_px is None:
        if result is None:
            raise ValueError("plot_epipolar: give tau_px or result (whose tau_px is used)")
        tau_px = float(np.asarray(result.tau_px))
    group = -1
    if result is not None:
        labels = np.asarray(result.labels)
        if labels.shape != mask.shape:
            raise ValueError(
                f"plot_epipolar: result must be one unbatched scene; labels {labels.shape}, mask {mask.shape}"
            )
        group = int(labels[view, slot])
        group = group if group >= 0 and bool(np.asarray(result.valid)[group]) else -1
        members = np.asarray(result.groups)[group] if group >= 0 else np.full(M, -1)
    truth = None if instance is None else np.asarray(instance)
    F = np.asarray(fundamental_from_rig(rig), dtype=np.float64)
    width, height = image_size
    point = np.array([*xy[view, slot], 1.0])
    pad = 0.04 * float(max(width, height))

    ncols = min(M, 5)
    nrows = math.ceil(M / ncols)
    panel_w = 3.0
    fig = Figure(
        figsize=(panel_w * ncols + 0.4, (panel_w * height / width + 0.6) * nrows + 1.5), dpi=100
    )
    FigureCanvasAgg(fig)
    gs = fig.add_gridspec(
        nrows,
        ncols,
        left=0.04,
        right=0.99,
        top=1 - 0.95 / fig.get_figheight(),
        bottom=0.75 / fig.get_figheight(),
        wspace=0.18,
        hspace=0.3,
    )
    for m in range(M):
        ax = fig.add_subplot(gs[divmod(m, ncols)])
        ax.add_patch(
            Rectangle(
                (0, 0), width, height, facecolor="#f4f4f4", edgecolor="0.35", lw=0.8, zorder=0
            )
        )
        pts = xy[m][mask[m]]
        slots = np.flatnonzero(mask[m])
        if m == view:
            ax.scatter(*pts.T, s=18, c=_UNASSIGNED_COLOR, zorder=2)
            ax.scatter(
                *xy[m, slot],
                s=160,
                marker="*",
                c=_LINE_COLOR,
                edgecolors="k",
                linewidths=0.6,
                zorder=4,
            )
            ax.set_title(
                f"view {m}: detection {slot}",
                fontsize=11,
                fontweight="bold",
                loc="left",
                color=_LINE_COLOR,
            )
        else:
            line = F[view, m] @ point
            norm = math.hypot(line[0], line[1])
            dist = np.abs(pts @ line[:2] + line[2]) / max(norm, 1e-300)
            inside = dist < tau_px
            nearest = int(np.argmin(dist)) if pts.size else None
            partner = None
            if truth is not None and truth[view, slot] >= 0:
                partner = slots[truth[m][slots] == truth[view, slot]]
            member = members[m] if group >= 0 and members[m] >= 0 else None
            # The band is a few pixels wide: an inset zooms on where the nearest detection meets it.
            zoom = None
            if nearest is not None and norm > 0 and dist[nearest] < 3.0 * tau_px:
                half = max(6.0 * tau_px, 10.0)
                foot = pts[nearest] - (pts[nearest] @ line[:2] + line[2]) / norm**2 * line[:2]
                zoom = ax.inset_axes((0.62, 0.02, 0.36, 0.36))
                zoom.set_xlim(foot[0] - half, foot[0] + half)
                zoom.set_ylim(foot[1] + half, foot[1] - half)
                zoom.set_aspect("equal")
                zoom.set_xticks([])
                zoom.set_yticks([])
                zoom.set_facecolor("white")
                for side in zoom.spines.values():
                    side.set_edgecolor(_LINE_COLOR)
                zoom.set_title(f"zoom ±{half:.0f} px", fontsize=7, pad=1.5, color=_LINE_COLOR)
            for a in (ax,) if zoom is None else (ax, zoom):
                if norm > 0:
                    a.add_patch(
                        Polygon(
                            _band_polygon(line, tau_px, float(width), float(height), pad),
                            closed=True,
                            facecolor=_LINE_COLOR,
                            alpha=0.18,
                            lw=0,
                            zorder=1,
                        )
                    )
                    a.plot(
                        *_band_polygon(line, 0.0, float(width), float(height), pad)[:2].T,
                        color=_LINE_COLOR,
                        lw=1.3,
                        zorder=2,
                    )
                a.scatter(*pts[~inside].T, s=18, c=_UNASSIGNED_COLOR, zorder=3)
                a.scatter(
                    *pts[inside].T,
                    s=30,
                    c=_CANDIDATE_COLOR,
                    edgecolors="k",
                    linewidths=0.5,
                    zorder=3,
                )
                if nearest is not None:
                    a.scatter(
                        *pts[nearest],
                        s=140,
                        facecolors="none",
                        edgecolors="k",
                        linewidths=1.4,
                        zorder=4,
                    )
                if member is not None:
                    a.scatter(
                        *xy[m, member],
                        s=60,
                        c=[group_style(group)[0]],
                        marker=group_style(group)[1],
                        edgecolors="k",
                        linewidths=0.8,
                        zorder=5,
                    )
                for j in () if partner is None else partner:
                    a.scatter(
                        *xy[m, j],
                        s=260,
                        facecolors="none",
                        edgecolors=_WRONG_COLOR,
                        linewidths=1.2,
                        linestyle="--",
                        zorder=4,
                    )
            text = f"{int(inside.sum())} in band"
            if nearest is not None:
                text += f", nearest {dist[nearest]:.1f} px"
            ax.set_title(f"view {m}", fontsize=11, fontweight="bold", loc="left")
            ax.set_title(text, fontsize=9, loc="right", color="0.3")
        ax.set_xlim(-pad, width + pad)
        ax.set_ylim(height + pad, -pad)
        ax.set_aspect("equal")
        ax.set_xticks(np.linspace(0, width, 3))
        ax.set_yticks(np.linspace(0, height, 3))
        ax.tick_params(labelsize=8, length=2, pad=1.5)

    where = f"group {group}" if group >= 0 else ("unassigned" if result is not None else "")
    fig.suptitle(
        f"Epipolar lines of detection {slot} of view {view}"
        f" {('(' + where + ')') if where else ''}   ·   τ = {tau_px:.2f} px",
        fontsize=13,
        fontweight="bold",
        y=1 - 0.15 / fig.get_figheight(),
        va="top",
    )

    def proxy(marker, **kw):
        return Line2D([], [], linestyle="none", marker=marker, **kw)

    handles = [
        Line2D([], [], color=_LINE_COLOR, lw=6, alpha=0.3),
        proxy("o", color=_CANDIDATE_COLOR, markeredgecolor="k"),
        proxy("o", markerfacecolor="none", markeredgecolor="k", markersize=11, markeredgewidth=1.4),
        proxy("o", color=_UNASSIGNED_COLOR),
    ]
    names = [
        "epipolar line and its ±τ band",
        "candidate: inside the band",
        "nearest detection (the only possible edge)",
        "other detection",
    ]
    if group >= 0:
        handles.append(
            proxy(group_style(group)[1], color=group_style(group)[0], markeredgecolor="k")
        )
        names.append(f"member of group {group} in the result")
    if truth is not None:
        handles.append(
            proxy("o", markerfacecolor="none", markeredgecolor=_WRONG_COLOR, markersize=13)
        )
        names.append("true partner (ground truth)")
    fig.legend(
        handles,
        names,
        loc="lower center",
        ncol=min(len(handles), 3),
        fontsize=10,
        frameon=False,
        bbox_to_anchor=(0.5, 0.0),
    )
    if path is not None:
        atomic_savefig(fig, path)
    return fig
