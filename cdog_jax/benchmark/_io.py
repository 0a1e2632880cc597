"""Sweep results on disk (NPZ + CSV + JSON) and the paper-style summary table (docs/BENCHMARK.md §2).

A results folder holds ``results.npz`` (every array), ``results.csv`` (one row per scene
and config, for spreadsheets and pandas) and ``results.json`` (grid, configs, versions,
device, timings). :func:`load_results` reads the NPZ and JSON back into an equal
:class:`SweepResult`; the CSV is an export only.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import os
from collections.abc import Sequence

import numpy as np

from .._expect import PATH, expect_args
from ..io._atomic import atomic_write
from ..metrics._scores import mean_metrics
from ._grid import Grid
from ._sweep import SweepResult

FORMAT_VERSION = 1
_SCENE_ARRAYS = ("sigma", "count", "scene", "num_points", "capacity")
_JSON_FIELDS = (
    "configs",
    "wall_s",
    "compile_s",
    "timing_s",
    "config_repr",
    "versions",
    "device",
    "num_devices",
    "buckets",
    "batch_size",
    "box",
)


def save_results(result: SweepResult, directory: str | os.PathLike) -> None:
    """Write ``result`` to ``directory`` (created if needed) as ``results.npz`` (all
    ``(S,)`` arrays and the rig), ``results.csv`` (one row per scene per config: config,
    σ, count, scene, every metric, time) and ``results.json`` (everything else)."""
    expect_args("save_results", result=(result, SweepResult), directory=(directory, PATH))
    os.makedirs(directory, exist_ok=True)
    arrays = {k: getattr(result, k) for k in _SCENE_ARRAYS}
    arrays.update({f"rig/{k}": v for k, v in result.rig.items()})
    for name in result.configs:
        arrays.update({f"metrics/{name}/{f}": v for f, v in result.metrics[name].items()})
        arrays[f"time_s/{name}"] = result.time_s[name]
    with atomic_write(os.path.join(directory, "results.npz"), "wb") as f:
        np.savez(f, **arrays)

    meta = {"format": FORMAT_VERSION, "grid": dataclasses.asdict(result.grid)}
    meta.update({k: getattr(result, k) for k in _JSON_FIELDS})
    meta["metric_order"] = {name: list(result.metrics[name]) for name in result.configs}
    with atomic_write(os.path.join(directory, "results.json"), "w") as f:
        json.dump(meta, f, indent=1, allow_nan=True)

    with atomic_write(os.path.join(directory, "results.csv"), "w", newline="") as f:
        writer = csv.writer(f)
        first = result.configs[0]
        fields = list(result.metrics[first])
        writer.writerow(["config", *_SCENE_ARRAYS, *fields, "time_s"])
        for name in result.configs:
            cols = [result.metrics[name][k] for k in fields]
            for i in range(result.num_scenes):
                scene = [_cell(getattr(result, k)[i]) for k in _SCENE_ARRAYS]
                writer.writerow(
                    [name, *scene, *(_cell(c[i]) for c in cols), _cell(result.time_s[name][i])]
                )


def _cell(v) -> str:
    """A CSV cell: booleans as 0/1, floats with repr (round-trips exactly)."""
    if isinstance(v, (bool, np.bool_)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    return str(int(v))


def load_results(directory: str | os.PathLike) -> SweepResult:
    """Read a folder written by :func:`save_results` back into a :class:`SweepResult`
    (arrays exactly as saved)."""
    expect_args("load_results", directory=(directory, PATH))
    with open(os.path.join(directory, "results.json")) as f:
        meta = json.load(f)
    if meta.get("format") != FORMAT_VERSION:
        raise ValueError(
            f"unknown results format {meta.get('format')!r} in {directory}; expected {FORMAT_VERSION}"
        )
    with np.load(os.path.join(directory, "results.npz"), allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    configs = tuple(meta["configs"])
    grid = {k: tuple(v) if isinstance(v, list) else v for k, v in meta["grid"].items()}
    return SweepResult(
        grid=Grid(**grid),
        configs=configs,
        **{k: arrays[k] for k in _SCENE_ARRAYS},
        metrics={
            n: {f: arrays[f"metrics/{n}/{f}"] for f in meta["metric_order"][n]} for n in configs
        },
        time_s={n: arrays[f"time_s/{n}"] for n in configs},
        wall_s=float(meta["wall_s"]),
        compile_s=float(meta["compile_s"]),
        timing_s=float(meta["timing_s"]),
        config_repr=dict(meta["config_repr"]),
        versions=dict(meta["versions"]),
        device=meta["device"],
        num_devices=int(meta["num_devices"]),
        buckets=tuple(meta["buckets"]),
        batch_size=tuple(meta["batch_size"]),
        box=tuple(tuple(float(v) for v in corner) for corner in meta["box"]),
        rig={k[len("rig/") :]: v for k, v in arrays.items() if k.startswith("rig/")},
    )


# Column title, mean_metrics key, format; docs/BENCHMARK.md §2 order.
_COLUMNS = (
    ("G-F1", "g_f1", "{:.3f}"),
    ("mP-F1", "mp_f1", "{:.3f}"),
    ("PG-P", "pg_p", "{:.3f}"),
    ("PG-R", "pg_r", "{:.3f}"),
    ("PG-F1", "pg_f1", "{:.3f}"),
    ("3DErr", "err3d", "{:.3f}"),
    ("BPE (px)", "bpe_px", "{:.2f}"),
    ("time (ms)", "time_ms", "{:.1f}"),
)


def summary_table(result: SweepResult, *, sigmas: Sequence[float] = (0.0, 1.0, 3.0, 5.0)) -> str:
    """A Markdown table of docs/BENCHMARK.md §2 columns per (σ, config), averaged over the scenes of
    that σ as :func:`cdog_jax.metrics.mean_metrics` does (3DErr and BPE over scenes with
    a scored group); time is the mean per-scene estimate in milliseconds. σ values absent
    from the grid are skipped."""
    expect_args("summary_table", result=(result, SweepResult))
    head = ["σ (px)", "method", *(c[0] for c in _COLUMNS)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for sigma in sigmas:
        where = np.isclose(result.sigma, float(sigma), rtol=0.0, atol=5e-4)
        if not where.any():
            continue
        for name in result.configs:
            means = mean_metrics(result.metrics_of(name, where=where))
            means["time_ms"] = 1000.0 * float(np.mean(result.time_s[name][where]))
            cells = [
                "–" if math.isnan(means[k]) else fmt.format(means[k]) for _, k, fmt in _COLUMNS
            ]
            lines.append(f"| {float(sigma):g} | {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)
