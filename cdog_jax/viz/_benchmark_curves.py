"""Benchmark figures as curves: metrics against σ beside the paper's and the original
code's numbers, time against point count, and the views ablation (the conventions of
``_benchmark_common.py``)."""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ._benchmark_common import (
    _ORIG_COLOR,
    _ORIGINAL_CODE,
    _ORIGINAL_TIME_COUNTS,
    _ORIGINAL_TIME_S,
    _PAPER_OURS,
    _PAPER_SIGMA_PX,
    _PAPER_VIEWS_PG_F1,
    _REF_COLOR,
    _as_1d,
    _as_fields,
    _checked,
    _finish,
    _fmt,
    _group_means,
    _is_score,
    _label,
    _method_colors,
    _new_figure,
    _per_method,
    scenes_for,
)

_TIME_NOTE = (
    "median over the scenes\nband: interquartile range\n\nevery scene is padded to its\nbucket's capacity P and timed\n"
    "at that size: the time is\nflat within a bucket"
)


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
        count: ``(S,)`` number of 3D points of every scene, or ``{method: (S_m,)}`` when the
            methods ran different scenes (e.g. a slow one on a sub-grid).
        time_s: ``{method: (S,)}`` (or ``(S_m,)``) per-scene association time in seconds (NaN: not timed).
        capacity: optional ``(S,)`` slot capacity (padded bucket) each scene ran at, or
            ``{method: (S_m,)}`` like ``count``.
        reference: draw the original code's timings.
        log: logarithmic time axis.
        path: if given, the figure is also saved there (PNG from the suffix).

    Returns:
        A :class:`matplotlib.figure.Figure` with one axes.
    """
    if not time_s:
        raise ValueError("time_s must hold at least one method")
    count_of = _per_method("count", count, list(time_s))
    # Tall enough for a legend entry (two lines) per method beside the axes.
    fig = _new_figure(9.6, max(4.8, 2.6 + 0.42 * len(time_s)), layout="constrained")
    ax = fig.add_subplot()
    colors = _method_colors(list(time_s))
    for method, t in time_s.items():
        count = count_of[method]
        t_ms = _as_1d(f"time_s[{method!r}]", t, count.size).astype(np.float64) * 1e3
        ok = np.isfinite(t_ms)
        counts = np.unique(count[ok])
        q = np.array(
            [np.percentile(t_ms[ok & (count == c)], (25, 50, 75)) for c in counts]
        ).reshape(-1, 3)
        color = colors[method]
        ax.fill_between(counts, q[:, 0], q[:, 2], color=color, alpha=0.22, lw=0)
        label = (
            f"{method}\n({q[-1, 1]:.3g} ms at {_fmt(counts[-1])} points)" if counts.size else method
        )
        ax.plot(counts, q[:, 1], color=color, lw=1.8, marker="o", ms=2.8, label=label)
    if reference:
        ax.plot(
            _ORIGINAL_TIME_COUNTS,
            np.array(_ORIGINAL_TIME_S) * 1e3,
            color=_REF_COLOR,
            ls="--",
            lw=1.2,
            marker="s",
            ms=6,
            mfc="white",
            mew=1.4,
            label="original code, full grid (docs/BENCHMARK.md §4)",
        )
        # Labels below-right of the first markers, above-left of the last: clear of the line.
        offsets = ((8, -3, "left", "top"), (8, -3, "left", "top"), (-9, 3, "right", "bottom"))
        for c, sec, (dx, dy, ha, va) in zip(_ORIGINAL_TIME_COUNTS, _ORIGINAL_TIME_S, offsets):
            ax.annotate(
                f"{sec:g} s",
                (c, sec * 1e3),
                textcoords="offset points",
                xytext=(dx, dy),
                ha=ha,
                va=va,
                fontsize=8,
                color=_REF_COLOR,
            )
    if capacity is not None:
        capacity_of = _per_method("capacity", capacity, list(time_s))
        for method, caps in capacity_of.items():
            _as_1d(f"capacity[{method!r}]", caps, count_of[method].size)
        for k, cap in enumerate(np.unique(np.concatenate(list(capacity_of.values())))):
            ax.axvline(
                cap, color="0.6", ls=":", lw=1.0, label="end of a padded bucket" if k == 0 else None
            )
            ax.annotate(
                f"P = {_fmt(cap)}",
                (cap, 0.0),
                xycoords=("data", "axes fraction"),
                xytext=(-3, 4),
                textcoords="offset points",
                ha="right",
                va="bottom",
                fontsize=8,
                color="0.4",
            )
    if log:
        ax.set_yscale("log")
    ax.set_xlim(left=0)
    ax.set_xlabel("3D points per scene", fontsize=10)
    ax.set_ylabel(
        "time per scene of its padded bucket (ms" + (", log scale)" if log else ")"), fontsize=10
    )
    ax.grid(True, which="major", color="0.88", lw=0.8)
    ax.grid(True, which="minor", axis="y", color="0.94", lw=0.5)
    ax.set_axisbelow(True)
    fig.legend(
        loc="outside right upper",
        fontsize=9,
        title=_TIME_NOTE,
        title_fontsize=8,
        frameon=False,
        labelspacing=0.9,
    )
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
        sigma: ``(S,)`` noise level of every scene (px), or ``{method: (S_m,)}`` when the
            methods ran different scenes (e.g. a slow one on a sub-grid).
        metrics: ``{method: {field: (S,)}}`` (or ``(S_m,)``) per-scene metrics.
        fields: the fields, one panel each.
        paper_reference: draw the paper's numbers.
        original_reference: draw the original code's numbers.
        full_grid: whether the scenes are the full benchmark grid (else a note in the title).
        path: if given, the figure is also saved there (PNG from the suffix).

    Returns:
        A :class:`matplotlib.figure.Figure`: one axes per field (the legend is the figure's).
    """
    metrics = _checked(metrics, fields)
    sigma_of = _per_method("sigma", sigma, list(metrics))
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
            sigma = sigma_of[method]
            values = _as_1d(f"metrics[{method!r}][{f!r}]", m[f], sigma.size).astype(np.float64)
            sigmas, means = _group_means(sigma, values, scenes_for(m, f))
            (h,) = ax.plot(
                sigmas, means, color=colors[method], lw=1.8, marker="o", ms=3, label=method
            )
            handles.setdefault(method, h)
        if original_reference and f in _ORIGINAL_CODE:
            (h,) = ax.plot(
                _PAPER_SIGMA_PX,
                _ORIGINAL_CODE[f],
                ls="none",
                marker="D",
                ms=6.5,
                mfc="white",
                mec=_ORIG_COLOR,
                mew=1.5,
                label="original code, full grid (docs/BENCHMARK.md §4)",
                zorder=4,
            )
            handles.setdefault(h.get_label(), h)
        if paper_reference and f in _PAPER_OURS:
            (h,) = ax.plot(
                _PAPER_SIGMA_PX,
                _PAPER_OURS[f],
                ls="none",
                marker="*",
                ms=11,
                color=_REF_COLOR,
                mec="white",
                mew=0.6,
                label="paper, full grid (docs/BENCHMARK.md §3)",
                zorder=5,
            )
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
    fig.legend(
        list(handles.values()),
        list(handles),
        loc="outside lower center",
        ncol=min(len(handles), 6),
        fontsize=9,
        frameon=False,
    )
    title = "Metrics vs noise (mean over all the scenes of each σ, all point counts)"
    if not full_grid and (paper_reference or original_reference):
        title += (
            "\nthis run is a smaller grid than the full benchmark; the paper's and the original code's "
            "markers average the full grid: a rough guide, not a like-for-like comparison"
        )
    fig.suptitle(title, fontsize=12 if full_grid else 11)
    return _finish(fig, path)


def views_ablation(
    views,
    values_by_method: Mapping[str, Any],
    *,
    field: str = "pg_f1",
    paper=_PAPER_VIEWS_PG_F1,
    sigma_px=3.0,
    path: str | os.PathLike | None = None,
):
    """A metric against the number of views (paper Table I), our methods vs the paper.

    Args:
        views: ``(S,)`` number of views of every scene (or of every value), or
            ``{method: (S_m,)}`` when the methods ran different scenes.
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
    if not values_by_method:
        raise ValueError("values_by_method must hold at least one method")
    views_of = _per_method("views", views, list(values_by_method))
    colors = _method_colors(list(values_by_method))
    fig = _new_figure(6.4, 4.4, layout="constrained")
    ax = fig.add_subplot()
    all_views = list(views_of.values())
    for method, v in values_by_method.items():
        views = views_of[method]
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
    if paper is _PAPER_VIEWS_PG_F1 and field != "pg_f1":
        paper = None  # Table I only reports PG-F1
    if paper is not None:
        paper_views = np.arange(2, 2 + len(paper))
        all_views.append(paper_views)
        ax.plot(
            paper_views,
            paper,
            color=_REF_COLOR,
            ls="--",
            lw=1.0,
            marker="*",
            ms=11,
            mec="white",
            mew=0.6,
            label="paper Table I (docs/BENCHMARK.md §3)",
        )
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
    ax.set_title(
        f"Views ablation at σ = {sigma_px:g} px: {_label(field, with_unit=False)}",
        fontsize=12,
        fontweight="bold",
        loc="left",
    )
    return _finish(fig, path)
