"""Figures of a benchmark sweep (docs/BENCHMARK.md §1 grid, docs/BENCHMARK.md §2 metrics, docs/BENCHMARK.md §3–4 reference numbers).

Host-side only, on plain arrays, so nothing here depends on how the sweep was run:

- ``sigma (S,)`` noise level of every scene (px) and ``count (S,)`` its number of 3D points;
- ``metrics[method][field] -> (S,)`` per-scene values, fields named as in
  :class:`cdog_jax.metrics.Metrics` (``pg_f1``, ``err3d``, ``num_err_groups``, ...); a
  ``Metrics`` batched over the scenes may stand in for the inner mapping;
- ``time_s[method] -> (S,)`` per-scene association time in seconds.

Averages follow docs/BENCHMARK.md §2 like :func:`cdog_jax.metrics.mean_metrics`: the plain mean over
scenes, except ``err3d`` and ``bpe_px``, which only average the scenes with
``num_err_groups > 0``. Every function returns a :class:`matplotlib.figure.Figure` bound to
the Agg canvas (headless, pyplot's global state untouched) and saves it when given ``path``.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..io._atomic import atomic_savefig

# Display name and unit of every Metrics field; a unit of None marks a score in [0, 1].
_FIELD_INFO = {
    "g_p": ("G-P", None),
    "g_r": ("G-R", None),
    "g_f1": ("G-F1", None),
    "g_iou": ("G-IoU", None),
    "mp_p": ("mP-P", None),
    "mp_r": ("mP-R", None),
    "mp_f1": ("mP-F1", None),
    "mp_iou": ("mP-IoU", None),
    "pg_p": ("PG-P", None),
    "pg_r": ("PG-R", None),
    "pg_f1": ("PG-F1", None),
    "err3d": ("3DErr", "scene units"),
    "bpe_px": ("BPE", "px"),
    "num_pred_groups": ("predicted groups (≥ 2 nodes)", "per scene"),
    "num_gt_groups": ("ground-truth groups", "per scene"),
    "num_unassigned": ("unassigned detections", "per scene"),
    "num_err_groups": ("groups scored by 3DErr/BPE", "per scene"),
    "has_groups": ("scenes with a group", None),
}
# Fields averaged only over scenes that have a group with a ground-truth point (docs/BENCHMARK.md §2).
_ERR_FIELDS = ("err3d", "bpe_px")

# docs/BENCHMARK.md §3–4: the paper's "Ours" row (10 views) and the original code measured on our benchmark.
_PAPER_SIGMA_PX = (0.0, 1.0, 3.0, 5.0)
_PAPER_OURS = {
    "g_f1": (0.950, 0.919, 0.881, 0.845),
    "mp_f1": (0.904, 0.839, 0.727, 0.609),
    "pg_p": (0.986, 0.955, 0.854, 0.733),
    "pg_r": (0.896, 0.821, 0.694, 0.571),
    "pg_f1": (0.937, 0.880, 0.761, 0.636),
    "err3d": (0.030, 0.087, 0.702, 0.787),
    "bpe_px": (2.51, 14.8, 15.6, 30.8),
}
_ORIGINAL_CODE = {
    "g_f1": (0.855, 0.752, 0.559, 0.405),
    "mp_f1": (0.994, 0.981, 0.895, 0.772),
    "pg_p": (0.982, 0.955, 0.828, 0.690),
    "pg_r": (0.891, 0.813, 0.655, 0.520),
    "pg_f1": (0.932, 0.875, 0.726, 0.588),
}
_ORIGINAL_TIME_COUNTS = (5, 40, 130)
_ORIGINAL_TIME_S = (0.06, 0.56, 4.6)
# PG-F1 of the paper's Table I for 2, 3, … 10 views (σ = 3 px).
PAPER_VIEWS_PG_F1 = (0.766, 0.726, 0.562, 0.601, 0.668, 0.685, 0.719, 0.747, 0.761)

_DPI = 120
_REF_COLOR = "0.1"
_ORIG_COLOR = "0.45"
_CMAP = "viridis"


# ----------------------------------------------------------------------------- averaging


def _as_1d(name: str, x, size: int | None = None) -> np.ndarray:
    x = np.asarray(x)
    if x.ndim != 1 or (size is not None and x.shape[0] != size):
        want = "(S,)" if size is None else f"(S,) with S={size}"
        raise ValueError(f"{name} must have shape {want}; got {x.shape}")
    return x


def _group_means(key, values, keep) -> tuple[np.ndarray, np.ndarray]:
    """Distinct ``key`` values (sorted) and the mean of ``values`` over the kept scenes of each
    (NaN where none is kept), by sums and counts so that empty groups raise no warning."""
    keys, inverse = np.unique(key, return_inverse=True)
    total = np.bincount(inverse, weights=np.where(keep, values, 0.0), minlength=keys.size)
    n = np.bincount(inverse, weights=keep.astype(np.float64), minlength=keys.size)
    return keys, np.divide(total, n, out=np.full(keys.size, np.nan), where=n > 0)


def cell_means(sigma, count, values, *, keep=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean of a per-scene value over the scenes of each (σ, point count) cell of the grid.

    Args:
        sigma: ``(S,)`` noise level of every scene (px).
        count: ``(S,)`` number of 3D points of every scene.
        values: ``(S,)`` per-scene value (e.g. one field of the metrics).
        keep: optional ``(S,)`` bool, the scenes that enter the mean (default: all); use
            :func:`scenes_for` to get the docs/BENCHMARK.md §2 rule for ``err3d``/``bpe_px``.

    Returns:
        ``sigmas (A,)`` and ``counts (C,)``, the sorted distinct values, and ``table (A, C)``
        of float64 means, NaN in a cell without (kept) scenes.
    """
    sigma = _as_1d("sigma", sigma)
    S = sigma.shape[0]
    count = _as_1d("count", count, S)
    values = _as_1d("values", values, S).astype(np.float64)
    keep = np.ones(S, bool) if keep is None else _as_1d("keep", keep, S).astype(bool)
    sigmas, si = np.unique(sigma, return_inverse=True)
    counts, ci = np.unique(count, return_inverse=True)
    cells, flat = _group_means(si * counts.size + ci, values, keep)  # only the occupied cells
    table = np.full(sigmas.size * counts.size, np.nan)
    table[cells] = flat
    return sigmas, counts, table.reshape(sigmas.size, counts.size)


def _cell_sizes(sigma, count) -> np.ndarray:
    """``(A, C)`` number of scenes in each (σ, count) cell."""
    sigmas, si = np.unique(np.asarray(sigma), return_inverse=True)
    counts, ci = np.unique(np.asarray(count), return_inverse=True)
    return np.bincount(si * counts.size + ci, minlength=sigmas.size * counts.size).reshape(sigmas.size, counts.size)


def scenes_for(method_metrics: Mapping[str, Any], field: str) -> np.ndarray:
    """Which scenes enter the average of ``field`` (docs/BENCHMARK.md §2).

    Args:
        method_metrics: ``{field: (S,)}`` per-scene metrics of one method.
        field: a :class:`cdog_jax.metrics.Metrics` field name.

    Returns:
        ``(S,)`` bool: ``num_err_groups > 0`` for ``err3d`` and ``bpe_px`` (scenes without a
        scored group have no 3D error), every scene for the other fields.
    """
    values = np.asarray(method_metrics[field])
    if field in _ERR_FIELDS:
        if "num_err_groups" not in method_metrics:
            raise ValueError(f"averaging {field!r} needs 'num_err_groups' in the metrics (docs/BENCHMARK.md §2)")
        return np.asarray(method_metrics["num_err_groups"]).reshape(values.shape) > 0
    return np.ones(values.shape, bool)


# ----------------------------------------------------------------------------- helpers


def _new_figure(width, height, **kw):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=_DPI, **kw)
    FigureCanvasAgg(fig)
    return fig


def _finish(fig, path):
    if path is not None:
        atomic_savefig(fig, path, dpi=_DPI)
    return fig


def _label(field: str, *, with_unit: bool = True) -> str:
    name, unit = _FIELD_INFO.get(field, (field, None))
    return f"{name} ({unit})" if with_unit and unit else name


def _is_score(field: str) -> bool:
    return field in _FIELD_INFO and _FIELD_INFO[field][1] is None


def _method_colors(methods: Sequence[str]) -> dict[str, Any]:
    from matplotlib import colormaps

    tab10 = colormaps["tab10"]
    return {m: tab10(i % 10) for i, m in enumerate(methods)}


def _as_fields(per_method) -> dict[str, Any]:
    """``{field: (S,)}`` from a mapping, or from a batched :class:`~cdog_jax.metrics.Metrics`."""
    if isinstance(per_method, Mapping):
        return dict(per_method)
    if dataclasses.is_dataclass(per_method):
        return {f.name: getattr(per_method, f.name) for f in dataclasses.fields(per_method)}
    raise ValueError(f"per-method metrics must be a mapping of fields or a Metrics; got {type(per_method)}")


def _checked(metrics: Mapping[str, Any], fields: Sequence[str]) -> dict[str, dict[str, Any]]:
    """The metrics as ``{method: {field: (S,)}}``, every method holding every field."""
    if not metrics:
        raise ValueError("metrics must hold at least one method")
    out = {}
    for method, per_method in metrics.items():
        out[method] = per_field = _as_fields(per_method)
        missing = [f for f in fields if f not in per_field]
        if missing:
            raise ValueError(f"metrics[{method!r}] lacks the fields {missing}; it has {sorted(per_field)}")
    return out


def _fmt(v) -> str:
    return f"{v:g}"


def _roundness(v: float) -> float:
    """The largest step of the ladder {1, 2, 5}·10^k (k ≥ -3) that divides ``v``."""
    if v == 0:
        return math.inf
    best = 0.0
    for k in range(-3, 7):
        for f in (1, 2, 5):
            step = f * 10.0**k
            q = v / step
            if round(q) != 0 and abs(q - round(q)) < 1e-6 * abs(q):
                best = step
    return best


def _category_ticks(values: np.ndarray, *, max_labels: int = 16, min_gap: int = 2) -> list[int]:
    """Indices of the categories to label on a categorical axis: all of them when few,
    otherwise the roundest values first (0, 100, 50, 10, 5, ...), at least ``min_gap``
    categories apart, plus the first one."""
    n = values.size
    if n <= max_labels:
        return list(range(n))
    diffs = np.diff(values.astype(np.float64))
    base = float(diffs[diffs > 0].min()) if (diffs > 0).any() else 1.0
    rounds = np.array([_roundness(float(v)) for v in values])
    candidates = [i for i in range(n) if rounds[i] >= 4 * base * (1 - 1e-9)]
    order = [0] + sorted(candidates, key=lambda i: (-rounds[i], i))
    chosen: list[int] = []
    for i in order:
        if all(abs(i - j) >= min_gap for j in chosen) and len(chosen) < max_labels:
            chosen.append(i)
    return sorted(chosen)


def _step_breaks(values: np.ndarray) -> list[int]:
    """Indices ``i`` where the spacing between categories ``i - 1`` and ``i`` changes."""
    d = np.diff(values.astype(np.float64))
    return [i + 1 for i in range(1, d.size) if not math.isclose(d[i], d[i - 1], rel_tol=1e-6)]


def _category_axis(values: np.ndarray, name: str, *, max_labels: int) -> tuple[list[int], list[int], str]:
    """Ticks, step breaks and axis label of a categorical axis. On a long axis whose spacing
    changes a few times (docs/BENCHMARK.md §1 counts: step 1 to 20, then 5) the breaks are marked and the
    label says so; a short axis labels every category and needs neither."""
    ticks = _category_ticks(values, max_labels=max_labels)
    breaks = _step_breaks(values)
    if len(ticks) == values.size or not breaks or len(breaks) > 3:
        return ticks, [], name
    d = np.diff(values.astype(np.float64))
    parts = [f"step {_fmt(d[0])}"]
    parts += [f"{_fmt(d[b])} from {_fmt(values[b])}" for b in breaks]
    return ticks, breaks, f"{name} (one column each: {', '.join(parts)})"


# ----------------------------------------------------------------------------- figures


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
    fig = _new_figure(ncols * (panel_w + 0.5) + 1.6, nrows * (panel_h + 0.9) + 0.7, layout="constrained")
    fig.get_layout_engine().set(w_pad=0.06, h_pad=0.08, wspace=0.03, hspace=0.06)
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
        im = ax.imshow(np.ma.masked_invalid(table), origin="lower", aspect="auto", cmap=cmap,
                       vmin=vmin, vmax=vmax if vmax > vmin else vmin + 1.0, interpolation="nearest")
        images.append(im)
        for b in x_breaks:
            ax.axvline(b - 0.5, color="white", lw=1.2, alpha=0.9)
        for b in y_breaks:
            ax.axhline(b - 0.5, color="white", lw=1.2, alpha=0.9)
        if A * C <= 80:  # few cells: print the values too
            for (i, j), v in np.ndenumerate(table):
                if np.isfinite(v):
                    light = im.norm(v) < 0.55
                    ax.text(j, i, f"{v:.2f}", ha="center", va="center", fontsize=7,
                            color="white" if light else "black")
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
        cb = fig.colorbar(images[0], ax=axes, fraction=0.03 if ncols > 1 else 0.06, pad=0.015, aspect=25)
        cb.set_label("score (mean over the scenes of a cell)", fontsize=9)
        cb.ax.tick_params(labelsize=8)
    lo, hi = int(n_scenes.min()), int(n_scenes.max())
    per = f"{lo}" if lo == hi else f"{lo}–{hi}"
    empty = any(not np.isfinite(t).all() for t in tables)
    fig.suptitle(f"{method}: mean over the scenes of each (σ, point count) cell  ·  {A} σ × {C} counts, "
                 f"{per} scenes per cell" + ("  ·  grey: no scene to average" if empty else ""), fontsize=12)
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
            ax.plot_surface(X, Y, table, facecolors=colors, rstride=1, cstride=1, linewidth=0.15,
                            edgecolor=(0.1, 0.1, 0.1, 0.25), shade=False, antialiased=True)
            ax.set_xlim(float(counts.min()), float(counts.max()))
            ax.set_ylim(float(sigmas.min()), float(sigmas.max()))
        else:  # a surface needs a 2 × 2 grid at least; say so rather than fail a whole report
            ax.text2D(0.5, 0.5, "needs ≥ 2 σ levels\nand ≥ 2 point counts", transform=ax.transAxes,
                      ha="center", va="center", fontsize=10, color="0.4")
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
    fig.suptitle(f"{method}: mean over the scenes of each (σ, point count) cell", fontsize=12, y=0.97)
    return _finish(fig, path)


_TIME_NOTE = ("median over the scenes\nband: interquartile range\n\nevery scene is padded to its\nbucket's capacity P and timed\n"
              "at that size: the time is\nflat within a bucket")


def time_vs_count(
    count,
    time_s: Mapping[str, Any],
    *,
    capacity=None,
    reference: bool = True,
    log: bool = True,
    path: str | os.PathLike | None = None,
):
    """Association time per scene against the number of 3D points, one line per method.

    Each line is the median over the scenes with that point count (all σ pooled), the band
    their interquartile range. The sweep times every capacity bucket as a whole, so a scene's
    time is that of its bucket's padded size: the curve is flat inside a bucket. The figure
    says so, and with ``capacity`` marks where each bucket ends. The original code's medians
    (docs/BENCHMARK.md §4: 0.06 s at 5 points, 0.56 s at 40, 4.6 s at 130) are drawn for
    reference.

    Args:
        count: ``(S,)`` number of 3D points of every scene.
        time_s: ``{method: (S,)}`` per-scene association time in seconds (NaN: not timed).
        capacity: optional ``(S,)`` slot capacity (padded bucket) each scene ran at.
        reference: draw the original code's timings.
        log: logarithmic time axis.
        path: if given, the figure is also saved there (PNG from the suffix).

    Returns:
        A :class:`matplotlib.figure.Figure` with one axes.
    """
    count = _as_1d("count", count)
    if not time_s:
        raise ValueError("time_s must hold at least one method")
    fig = _new_figure(9.6, 4.8, layout="constrained")
    ax = fig.add_subplot()
    colors = _method_colors(list(time_s))
    for method, t in time_s.items():
        t_ms = _as_1d(f"time_s[{method!r}]", t, count.size).astype(np.float64) * 1e3
        ok = np.isfinite(t_ms)
        counts = np.unique(count[ok])
        q = np.array([np.percentile(t_ms[ok & (count == c)], (25, 50, 75)) for c in counts]).reshape(-1, 3)
        color = colors[method]
        ax.fill_between(counts, q[:, 0], q[:, 2], color=color, alpha=0.22, lw=0)
        label = f"{method}\n({q[-1, 1]:.3g} ms at {_fmt(counts[-1])} points)" if counts.size else method
        ax.plot(counts, q[:, 1], color=color, lw=1.8, marker="o", ms=2.8, label=label)
    if reference:
        ax.plot(_ORIGINAL_TIME_COUNTS, np.array(_ORIGINAL_TIME_S) * 1e3, color=_REF_COLOR, ls="--", lw=1.2,
                marker="s", ms=6, mfc="white", mew=1.4, label="original code, full grid (docs/BENCHMARK.md §4)")
        # Labels below-right of the first markers, above-left of the last: clear of the line.
        offsets = ((8, -3, "left", "top"), (8, -3, "left", "top"), (-9, 3, "right", "bottom"))
        for c, sec, (dx, dy, ha, va) in zip(_ORIGINAL_TIME_COUNTS, _ORIGINAL_TIME_S, offsets):
            ax.annotate(f"{sec:g} s", (c, sec * 1e3), textcoords="offset points", xytext=(dx, dy), ha=ha,
                        va=va, fontsize=8, color=_REF_COLOR)
    if capacity is not None:
        capacity = _as_1d("capacity", capacity, count.size)
        for k, cap in enumerate(np.unique(capacity)):
            ax.axvline(cap, color="0.6", ls=":", lw=1.0, label="end of a padded bucket" if k == 0 else None)
            ax.annotate(f"P = {_fmt(cap)}", (cap, 0.0), xycoords=("data", "axes fraction"), xytext=(-3, 4),
                        textcoords="offset points", ha="right", va="bottom", fontsize=8, color="0.4")
    if log:
        ax.set_yscale("log")
    ax.set_xlim(left=0)
    ax.set_xlabel("3D points per scene", fontsize=10)
    ax.set_ylabel("time per scene of its padded bucket (ms" + (", log scale)" if log else ")"), fontsize=10)
    ax.grid(True, which="major", color="0.88", lw=0.8)
    ax.grid(True, which="minor", axis="y", color="0.94", lw=0.5)
    ax.set_axisbelow(True)
    fig.legend(loc="outside right upper", fontsize=9, title=_TIME_NOTE,
               title_fontsize=8, frameon=False, labelspacing=0.9)
    ax.set_title("Association time vs scene size", fontsize=12, fontweight="bold", loc="left")

    return _finish(fig, path)


def metrics_vs_sigma(
    sigma,
    metrics: Mapping[str, Any],
    *,
    fields: Sequence[str] = ("pg_f1", "mp_f1", "g_f1", "pg_p", "pg_r"),
    paper_reference: bool = True,
    original_reference: bool = True,
    full_grid: bool = True,
    path: str | os.PathLike | None = None,
):
    """Mean metrics against the noise level, one panel per field, one line per method.

    Every point averages all the scenes of that σ (all point counts, docs/BENCHMARK.md §2 rule for
    ``err3d``/``bpe_px``). The reference numbers at σ = 0, 1, 3, 5 are drawn as markers where
    the field has them: the paper's "Ours" row (docs/BENCHMARK.md §3) and the original code
    measured on our benchmark (§4). Both average a full grid; with ``full_grid=False`` (a
    quick or narrowed grid) the title says that the comparison is only a rough guide.

    Args:
        sigma: ``(S,)`` noise level of every scene (px).
        metrics: ``{method: {field: (S,)}}`` per-scene metrics.
        fields: the fields, one panel each.
        paper_reference: draw the paper's numbers.
        original_reference: draw the original code's numbers.
        full_grid: whether the scenes are the full benchmark grid (else a note in the title).
        path: if given, the figure is also saved there (PNG from the suffix).

    Returns:
        A :class:`matplotlib.figure.Figure`: one axes per field (the legend is the figure's).
    """
    sigma = _as_1d("sigma", sigma)
    metrics = _checked(metrics, fields)
    colors = _method_colors(list(metrics))
    n = len(fields)
    ncols = n if n <= 5 else math.ceil(n / 2)
    nrows = math.ceil(n / ncols)
    fig = _new_figure(3.3 * ncols + 0.4, 3.0 * nrows + 0.9, layout="constrained")
    fig.get_layout_engine().set(w_pad=0.05, h_pad=0.05, wspace=0.04, hspace=0.06)
    handles: dict[str, Any] = {}
    for k, f in enumerate(fields):
        ax = fig.add_subplot(nrows, ncols, k + 1)
        for method, m in metrics.items():
            values = _as_1d(f"metrics[{method!r}][{f!r}]", m[f], sigma.size).astype(np.float64)
            sigmas, means = _group_means(sigma, values, scenes_for(m, f))
            (h,) = ax.plot(sigmas, means, color=colors[method], lw=1.8, marker="o", ms=3, label=method)
            handles.setdefault(method, h)
        if original_reference and f in _ORIGINAL_CODE:
            (h,) = ax.plot(_PAPER_SIGMA_PX, _ORIGINAL_CODE[f], ls="none", marker="D", ms=6.5, mfc="white",
                           mec=_ORIG_COLOR, mew=1.5, label="original code, full grid (docs/BENCHMARK.md §4)", zorder=4)
            handles.setdefault(h.get_label(), h)
        if paper_reference and f in _PAPER_OURS:
            (h,) = ax.plot(_PAPER_SIGMA_PX, _PAPER_OURS[f], ls="none", marker="*", ms=11, color=_REF_COLOR,
                           mec="white", mew=0.6, label="paper, full grid (docs/BENCHMARK.md §3)", zorder=5)
            handles.setdefault(h.get_label(), h)
        if _is_score(f):
            lo, hi = ax.get_ylim()
            ax.set_ylim(max(lo, 0.0), min(hi, 1.0) + 0.02)
        else:
            ax.set_ylim(bottom=0.0)
        ax.set_xlabel("noise σ (px)", fontsize=9)
        ax.set_ylabel(_label(f), fontsize=9)
        ax.set_title(_label(f, with_unit=False), fontsize=12, fontweight="bold", loc="left")
        ax.grid(True, color="0.9", lw=0.8)
        ax.set_axisbelow(True)
        ax.tick_params(labelsize=8)
    fig.legend(list(handles.values()), list(handles), loc="outside lower center", ncol=min(len(handles), 6),
               fontsize=9, frameon=False)
    title = "Metrics vs noise (mean over all the scenes of each σ, all point counts)"
    if not full_grid and (paper_reference or original_reference):
        title += ("\nthis run is a smaller grid than the full benchmark; the paper's and the original code's "
                  "markers average the full grid: a rough guide, not a like-for-like comparison")
    fig.suptitle(title, fontsize=12 if full_grid else 11)
    return _finish(fig, path)


def views_ablation(
    views,
    values_by_method: Mapping[str, Any],
    *,
    field: str = "pg_f1",
    paper=PAPER_VIEWS_PG_F1,
    sigma_px=3.0,
    path: str | os.PathLike | None = None,
):
    """A metric against the number of views (paper Table I), our methods vs the paper.

    Args:
        views: ``(S,)`` number of views of every scene (or of every value).
        values_by_method: ``{method: values}``, where ``values`` is either ``(S,)`` (already
            the chosen field) or ``{field: (S,)}`` per-scene metrics. Values with the same
            view count are averaged (docs/BENCHMARK.md §2 rule for ``err3d``/``bpe_px`` when the metrics
            dict is given).
        field: the field drawn (its name labels the axis).
        paper: the paper's values for 2, 3, … views (default: Table I PG-F1 at σ = 3,
            2…10 views, drawn only when ``field`` is ``"pg_f1"``); ``None`` draws none.
        sigma_px: the noise level of the ablation, for the title.
        path: if given, the figure is also saved there (PNG from the suffix).

    Returns:
        A :class:`matplotlib.figure.Figure` with one axes.
    """
    views = _as_1d("views", views)
    if not values_by_method:
        raise ValueError("values_by_method must hold at least one method")
    colors = _method_colors(list(values_by_method))
    fig = _new_figure(6.4, 4.4, layout="constrained")
    ax = fig.add_subplot()
    all_views = [views]
    for method, v in values_by_method.items():
        if isinstance(v, Mapping) or dataclasses.is_dataclass(v):
            v = _as_fields(v)
            if field not in v:
                raise ValueError(f"values_by_method[{method!r}] lacks the field {field!r}")
            keep, values = scenes_for(v, field), np.asarray(v[field])
        else:
            values = np.asarray(v)
            keep = np.ones(values.shape, bool)
        values = _as_1d(f"values_by_method[{method!r}]", values, views.size).astype(np.float64)
        xs, means = _group_means(views, values, keep)
        ax.plot(xs, means, color=colors[method], lw=1.8, marker="o", ms=5, label=method)
    if paper is PAPER_VIEWS_PG_F1 and field != "pg_f1":
        paper = None  # Table I only reports PG-F1
    if paper is not None:
        paper_views = np.arange(2, 2 + len(paper))
        all_views.append(paper_views)
        ax.plot(paper_views, paper, color=_REF_COLOR, ls="--", lw=1.0, marker="*", ms=11, mec="white", mew=0.6,
                label="paper Table I (docs/BENCHMARK.md §3)")
    xs = np.unique(np.concatenate(all_views))
    ax.set_xticks(xs)
    if _is_score(field):
        lo, hi = ax.get_ylim()
        ax.set_ylim(max(lo, 0.0), min(hi, 1.0) + 0.02)
    ax.set_xlabel("number of views (sampled at random from the rig)", fontsize=10)
    ax.set_ylabel(_label(field), fontsize=10)
    ax.grid(True, color="0.9", lw=0.8)
    ax.set_axisbelow(True)
    ax.legend(fontsize=9, loc="lower right", framealpha=0.9)
    ax.set_title(f"Views ablation at σ = {sigma_px:g} px: {_label(field, with_unit=False)}", fontsize=12,
                 fontweight="bold", loc="left")
    return _finish(fig, path)
