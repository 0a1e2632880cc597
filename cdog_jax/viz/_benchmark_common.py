"""What every figure of a benchmark sweep shares (docs/BENCHMARK.md §1 grid, docs/BENCHMARK.md §2 metrics, docs/BENCHMARK.md §3–4 reference numbers).

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
_PAPER_VIEWS_PG_F1 = (0.766, 0.726, 0.562, 0.601, 0.668, 0.685, 0.719, 0.747, 0.761)

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
    return np.bincount(si * counts.size + ci, minlength=sigmas.size * counts.size).reshape(
        sigmas.size, counts.size
    )


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
            raise ValueError(
                f"averaging {field!r} needs 'num_err_groups' in the metrics (docs/BENCHMARK.md §2)"
            )
        return np.asarray(method_metrics["num_err_groups"]).reshape(values.shape) > 0
    return np.ones(values.shape, bool)


# ----------------------------------------------------------------------------- helpers


def _new_figure(width, height, **kw):
    # matplotlib loads with the first figure: importing the package stays quick
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
    """One colour per method: tab10 up to 10 methods, tab20 beyond (cycled past 20)."""
    # matplotlib loads with the first figure: importing the package stays quick
    from matplotlib import colormaps

    cmap, n = (colormaps["tab10"], 10) if len(methods) <= 10 else (colormaps["tab20"], 20)
    return {m: cmap(i % n) for i, m in enumerate(methods)}


def _per_method(name: str, x, methods: Sequence[str]) -> dict[str, np.ndarray]:
    """``{method: (S_m,)}``: ``x`` itself for every method when it is one ``(S,)`` array (all
    methods ran the same scenes), else ``x[method]`` (each method its own scenes)."""
    if isinstance(x, Mapping):
        missing = [m for m in methods if m not in x]
        if missing:
            raise ValueError(f"{name} is a mapping per method but lacks {missing}")
        return {m: _as_1d(f"{name}[{m!r}]", x[m]) for m in methods}
    x = _as_1d(name, x)
    return {m: x for m in methods}


def _as_fields(per_method) -> dict[str, Any]:
    """``{field: (S,)}`` from a mapping, or from a batched :class:`~cdog_jax.metrics.Metrics`."""
    if isinstance(per_method, Mapping):
        return dict(per_method)
    if dataclasses.is_dataclass(per_method):
        return {f.name: getattr(per_method, f.name) for f in dataclasses.fields(per_method)}
    raise ValueError(
        f"per-method metrics must be a mapping of fields or a Metrics; got {type(per_method)}"
    )


def _checked(metrics: Mapping[str, Any], fields: Sequence[str]) -> dict[str, dict[str, Any]]:
    """The metrics as ``{method: {field: (S,)}}``, every method holding every field."""
    if not metrics:
        raise ValueError("metrics must hold at least one method")
    out = {}
    for method, per_method in metrics.items():
        out[method] = per_field = _as_fields(per_method)
        missing = [f for f in fields if f not in per_field]
        if missing:
            raise ValueError(
                f"metrics[{method!r}] lacks the fields {missing}; it has {sorted(per_field)}"
            )
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


def _category_axis(
    values: np.ndarray, name: str, *, max_labels: int
) -> tuple[list[int], list[int], str]:
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
