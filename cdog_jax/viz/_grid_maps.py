"""Benchmark figures over the σ × point-count grid: heat maps and 3D surfaces of a score
per method (the conventions of ``_benchmark_common.py``)."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ._benchmark_common import (
    _CMAP,
    _FIELD_INFO,
    _as_1d,
    _category_axis,
    _cell_sizes,
    _checked,
    _finish,
    _fmt,
    _is_score,
    _label,
    _new_figure,
    cell_means,
    scenes_for,
)


def heatmaps(
    sigma,
    count,
    metrics: Mapping[str, Any],
    *,
    method: str,
    fields: Sequence[str] = ("pg_f1", "mp_f1", "g_f1"),
    path: str | os.PathLike | None = None,
):
    """Heat maps over the σ × point count grid of one method, one panel per field.

    Rows are noise levels, columns point counts, as categories (the docs/BENCHMARK.md §1 counts step by 1
    up to 20, then by 5; a white line marks where the step changes). Scores share one colour
    scale 0–1; other fields (``err3d``, ``bpe_px``) get their own colour bar.

    Args:
        sigma: ``(S,)`` noise level of every scene (px).
        count: ``(S,)`` number of 3D points of every scene.
        metrics: ``{method: {field: (S,)}}`` per-scene metrics.
        method: the method to draw.
        fields: the fields, one panel each.
        path: if given, the figure is also saved there (PNG from the suffix).

    Returns:
        A :class:`matplotlib.figure.Figure`: one axes per field, then the colour bar(s).
    """
    if method not in metrics:
        raise ValueError(f"method must be one of {list(metrics)}; got {method!r}")
    sigma = _as_1d("sigma", sigma)
    m = _checked(metrics, fields)[method]
    tables = []
    for f in fields:
        values = _as_1d(f"metrics[{method!r}][{f!r}]", m[f], sigma.size)
        sigmas, counts, table = cell_means(sigma, count, values, keep=scenes_for(m, f))
        tables.append(table)
    sizes = _cell_sizes(sigma, count)
    n_scenes = np.unique(sizes[sizes > 0])
    all_scores = all(_is_score(f) for f in fields)

    n = len(fields)
    ncols = min(n, 3)
    nrows = math.ceil(n / ncols)
    A, C = sigmas.size, counts.size
    # Size the panels to the grid so cells stay roughly square (capped for huge grids).
    panel_w = float(np.clip(0.11 * C, 2.6, 4.8))
    panel_h = float(np.clip(0.15 * A, 1.8, 3.4))
    fig = _new_figure(
        ncols * (panel_w + 0.5) + 1.6, nrows * (panel_h + 0.9) + 0.7, layout="constrained"
    )
    fig.get_layout_engine().set(w_pad=0.06, h_pad=0.08, wspace=0.03, hspace=0.06)
    # matplotlib loads with the first figure: importing the package stays quick
    from matplotlib import colormaps

    cmap = colormaps[_CMAP].with_extremes(bad="0.82")
    axes, images = [], []
    x_ticks, x_breaks, x_label = _category_axis(counts, "3D points per scene", max_labels=16)
    y_ticks, y_breaks, y_label = _category_axis(sigmas, "noise σ (px)", max_labels=12)
    for k, (f, table) in enumerate(zip(fields, tables)):
        ax = fig.add_subplot(nrows, ncols, k + 1)
        if _is_score(f):
            vmin, vmax = 0.0, 1.0
        else:
            finite = table[np.isfinite(table)]
            vmin, vmax = (0.0, float(finite.max())) if finite.size else (0.0, 1.0)
        im = ax.imshow(
            np.ma.masked_invalid(table),
            origin="lower",
            aspect="auto",
            cmap=cmap,
            vmin=vmin,
            vmax=vmax if vmax > vmin else vmin + 1.0,
            interpolation="nearest",
        )
        images.append(im)
        for b in x_breaks:
            ax.axvline(b - 0.5, color="white", lw=1.2, alpha=0.9)
        for b in y_breaks:
            ax.axhline(b - 0.5, color="white", lw=1.2, alpha=0.9)
        if A * C <= 80:  # few cells: print the values too
            for (i, j), v in np.ndenumerate(table):
                if np.isfinite(v):
                    light = im.norm(v) < 0.55
                    ax.text(
                        j,
                        i,
                        f"{v:.2f}",
                        ha="center",
                        va="center",
                        fontsize=7,
                        color="white" if light else "black",
                    )
        ax.set_xticks(x_ticks, [_fmt(counts[i]) for i in x_ticks])
        ax.set_yticks(y_ticks, [_fmt(sigmas[i]) for i in y_ticks])
        ax.set_xticks(np.arange(C), minor=True)
        ax.set_yticks(np.arange(A), minor=True)
        ax.tick_params(labelsize=8)
        ax.tick_params(axis="x", labelsize=7.5)
        ax.tick_params(which="minor", length=1.5)
        ax.set_xlabel(x_label, fontsize=9)
        ax.set_ylabel(y_label, fontsize=9)
        mean = float(np.nanmean(table)) if np.isfinite(table).any() else float("nan")
        ax.set_title(_label(f), fontsize=12, fontweight="bold", loc="left")
        ax.set_title(f"mean of the cells {mean:.3g}", fontsize=8, loc="right", color="0.35")
        if not all_scores:
            cb = fig.colorbar(im, ax=ax, fraction=0.05, pad=0.02)
            cb.set_label(_label(f), fontsize=9)
            cb.ax.tick_params(labelsize=8)
        axes.append(ax)
    if all_scores:
        cb = fig.colorbar(
            images[0], ax=axes, fraction=0.03 if ncols > 1 else 0.06, pad=0.015, aspect=25
        )
        cb.set_label("score (mean over the scenes of a cell)", fontsize=9)
        cb.ax.tick_params(labelsize=8)
    lo, hi = int(n_scenes.min()), int(n_scenes.max())
    per = f"{lo}" if lo == hi else f"{lo}–{hi}"
    empty = any(not np.isfinite(t).all() for t in tables)
    fig.suptitle(
        f"{method}: mean over the scenes of each (σ, point count) cell  ·  {A} σ × {C} counts, "
        f"{per} scenes per cell" + ("  ·  grey: no scene to average" if empty else ""),
        fontsize=12,
    )
    return _finish(fig, path)


def surfaces(
    sigma,
    count,
    metrics: Mapping[str, Any],
    *,
    method: str,
    fields: Sequence[str] = ("pg_f1", "mp_f1", "g_f1"),
    path: str | os.PathLike | None = None,
):
    """The paper's 3D score surfaces: cell mean over (point count, σ), one panel per field.

    Args:
        sigma: ``(S,)`` noise level of every scene (px).
        count: ``(S,)`` number of 3D points of every scene.
        metrics: ``{method: {field: (S,)}}`` per-scene metrics.
        method: the method to draw.
        fields: the fields, one 3D panel each (scores share the 0–1 colour scale).
        path: if given, the figure is also saved there (PNG from the suffix).

    Returns:
        A :class:`matplotlib.figure.Figure`: one 3D axes per field, then the colour bar.
    """
    if method not in metrics:
        raise ValueError(f"method must be one of {list(metrics)}; got {method!r}")
    sigma = _as_1d("sigma", sigma)
    m = _checked(metrics, fields)[method]
    # matplotlib loads with the first figure: importing the package stays quick
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    n = len(fields)
    all_scores = all(_is_score(f) for f in fields)
    fig = _new_figure(4.6 * n + 1.0 if all_scores else 5.6 * n, 4.9)
    cmap = colormaps[_CMAP]
    axes = []
    width = (0.9 if all_scores else 0.98) / n
    for k, f in enumerate(fields):
        values = _as_1d(f"metrics[{method!r}][{f!r}]", m[f], sigma.size)
        sigmas, counts, table = cell_means(sigma, count, values, keep=scenes_for(m, f))
        X, Y = np.meshgrid(counts.astype(np.float64), sigmas.astype(np.float64))
        if _is_score(f):
            zmax = 1.0
        else:
            finite = table[np.isfinite(table)]
            zmax = float(finite.max()) if finite.size and finite.max() > 0 else 1.0
        norm = Normalize(0.0, zmax)
        # Cells without scenes are NaN: plot_surface leaves their quads out (a hole).
        colors = cmap(norm(np.nan_to_num(table)))
        if all_scores:  # one colour bar on the right
            rect = (0.03 + k * width, 0.05, 0.97 * width, 0.82)
        else:  # a colour bar in each panel's slot, clear of the next panel's z label
            rect = ((k + 0.08) * width, 0.05, 0.74 * width, 0.82)
        ax = fig.add_axes(rect, projection="3d")
        if sigmas.size >= 2 and counts.size >= 2:
            ax.plot_surface(
                X,
                Y,
                table,
                facecolors=colors,
                rstride=1,
                cstride=1,
                linewidth=0.15,
                edgecolor=(0.1, 0.1, 0.1, 0.25),
                shade=False,
                antialiased=True,
            )
            ax.set_xlim(float(counts.min()), float(counts.max()))
            ax.set_ylim(float(sigmas.min()), float(sigmas.max()))
        else:  # a surface needs a 2 × 2 grid at least; say so rather than fail a whole report
            ax.text2D(
                0.5,
                0.5,
                "needs ≥ 2 σ levels\nand ≥ 2 point counts",
                transform=ax.transAxes,
                ha="center",
                va="center",
                fontsize=10,
                color="0.4",
            )
        ax.set_zlim(0.0, zmax)
        ax.set_xlabel("3D points per scene", fontsize=9, labelpad=2)
        ax.set_ylabel("noise σ (px)", fontsize=9, labelpad=2)
        ax.set_zlabel(_FIELD_INFO.get(f, (f, None))[1] or "score", fontsize=9, labelpad=2)
        ax.tick_params(labelsize=7, pad=0)
        # Look from the worst corner (high σ for scores, low σ for errors) so the surface
        # rises away from the viewer and its top face shows.
        ax.view_init(elev=30, azim=50 if _is_score(f) else -130)
        ax.set_title(_label(f), fontsize=12, fontweight="bold", y=1.0)
        axes.append(ax)
        if not all_scores:
            cax = fig.add_axes((0.025 + (k + 0.84) * width, 0.22, 0.008, 0.5))
            cb = fig.colorbar(ScalarMappable(norm, cmap), cax=cax)
            cb.set_label(_label(f), fontsize=8)
            cb.ax.tick_params(labelsize=7)
    if all_scores:
        cax = fig.add_axes((0.925, 0.2, 0.012, 0.55))
        cb = fig.colorbar(ScalarMappable(Normalize(0.0, 1.0), cmap), cax=cax)
        cb.set_label("score, mean over the scenes of a cell", fontsize=9)
        cb.ax.tick_params(labelsize=8)
    fig.suptitle(
        f"{method}: mean over the scenes of each (σ, point count) cell", fontsize=12, y=0.97
    )
    return _finish(fig, path)
