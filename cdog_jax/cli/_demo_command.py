"""``cdog-jax demo``: the built-in rig → a synthetic scene → :func:`cdog_jax.associate` →
summary, metrics (docs/BENCHMARK.md §2), timings and a PNG figure; ``--save-scene`` writes
the scene as files that ``cdog-jax associate`` reads."""

from __future__ import annotations

import argparse
import json
import math
import os
import time

import jax
import numpy as np

from .. import associate, method_from
from .._runtime.xla_kernels import jit
from ..io import save_detections_json, save_rig
from ..io._atomic import atomic_write
from ._common import (
    _FIGURE_EXTENSIONS,
    _emit,
    _nonnegative_float,
    _positive_int,
    add_method_argument,
    check_sigma_fits,
    seed_int,
)
from ._paths import check_output, check_output_folder, write_output

# Rows of the metrics table: (Metrics field, docs/BENCHMARK.md §2 name, format, unit / meaning).
_METRIC_ROWS = (
    ("g_f1", "G-F1", ".3f", "group level, imperfect groups allowed"),
    ("mp_f1", "mP-F1", ".3f", "mean point F1 over groups of >= 2 nodes"),
    ("pg_p", "PG-P", ".3f", "perfect-group precision"),
    ("pg_r", "PG-R", ".3f", "perfect-group recall"),
    ("pg_f1", "PG-F1", ".3f", "perfect-group F1"),
    ("err3d", "3DErr", ".4f", "scene units, triangulated vs true 3D point"),
    ("bpe_px", "BPE", ".3f", "px, reprojection vs noise-free projection"),
)


def _seconds(s: float) -> str:
    return f"{s * 1e3:.1f} ms" if s < 1.0 else f"{s:.2f} s"


def add_parser(subparsers) -> None:
    """Declare ``demo`` and its flags."""
    p = subparsers.add_parser(
        "demo",
        help="associate a synthetic scene on the built-in rig, print metrics, save a figure",
        description=(
            "Generate a synthetic scene on the built-in 10-camera rig, associate it with C-DOG, print a "
            "summary with the benchmark's metrics (defined in docs/BENCHMARK.md) and timings, and write a "
            "figure. --save-scene DIR also writes the scene as files that 'cdog-jax associate' reads."
        ),
    )
    p.add_argument(
        "--points", type=_positive_int, default=60, help="3D points in the scene (default 60)"
    )
    p.add_argument(
        "--sigma", type=_nonnegative_float, default=1.0, help="pixel noise std σ (default 1.0)"
    )
    add_method_argument(p)
    p.add_argument("--seed", type=seed_int, default=0, help="PRNG seed of the scene (default 0)")
    p.add_argument(
        "--sigma-auto",
        action="store_true",
        help="estimate σ from the detections instead of using --sigma (which still sets the scene noise)",
    )
    p.add_argument(
        "--out",
        default="cdog_demo.png",
        help="output figure, .png/.pdf/.svg/.jpg (default cdog_demo.png)",
    )
    p.add_argument(
        "--capacity", type=_positive_int, default=None, help="slots per view P (default: --points)"
    )
    p.add_argument(
        "--save-scene",
        metavar="DIR",
        default=None,
        help="also write the scene into DIR: rig.json, detections.json (input of 'cdog-jax associate') and "
        "truth.json (the true 3D points and the point of every detection); refused where DIR holds "
        "one of them already, unless --force",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="let --save-scene replace the rig.json, detections.json and truth.json that DIR holds",
    )
    p.set_defaults(func=run, parser=p)


_SCENE_FILES = ("rig.json", "detections.json", "truth.json")


def _save_scene(folder: str, rig, scene, sigma: float, seed: int) -> None:
    """Write ``scene`` (unbatched) into ``folder`` as ``rig.json``, ``detections.json`` and
    ``truth.json``; the truth lists the point id of every detection in the order of
    ``detections.json`` and the true 3D points (scene units)."""
    from ..synthetic import IMAGE_SIZE  # the synthetic scenes load when the demo runs

    os.makedirs(folder, exist_ok=True)
    mask = np.asarray(scene.mask)
    instance = np.asarray(scene.instance)
    save_rig(os.path.join(folder, "rig.json"), rig, format="json", image_size=IMAGE_SIZE)
    save_detections_json(os.path.join(folder, "detections.json"), scene.xy, mask)
    truth = {
        "about": "synthetic scene of 'cdog-jax demo': views[m][k] is the true point of detection k of view m "
        "in detections.json; points3d[i] is point i (scene units)",
        "sigma_px": sigma,
        "seed": seed,
        "points3d": np.asarray(scene.points3d, dtype=np.float64)[: int(scene.num_points)].tolist(),
        "views": [instance[m][mask[m]].tolist() for m in range(mask.shape[0])],
    }
    with atomic_write(os.path.join(folder, "truth.json"), "w") as f:
        json.dump(truth, f)
        f.write("\n")


def run(args: argparse.Namespace) -> int:
    # The scenes, their scores and the figure (matplotlib) load when the demo runs.
    from ..metrics import scene_metrics
    from ..synthetic import IMAGE_SIZE, default_rig, generate_scene
    from ..viz import plot_association

    capacity = args.points if args.capacity is None else args.capacity
    if capacity < args.points:
        args.parser.error(f"--capacity must be >= --points ({args.points}); got {capacity}")
    check_output(args.out, "--out", _FIGURE_EXTENSIONS, {})
    if args.save_scene is not None:
        check_output_folder(args.save_scene, "--save-scene", _SCENE_FILES, {}, replace=args.force)
    check_sigma_fits(
        args.sigma,
        math.hypot(*IMAGE_SIZE),
        f"the built-in rig ({IMAGE_SIZE[0]}×{IMAGE_SIZE[1]} px)",
    )
    config = method_from(args.method, "cdog-jax demo")
    sigma_arg = "auto" if args.sigma_auto else args.sigma
    timings: list[tuple[str, float]] = []

    def timed(label, fn, *a, **kw):
        t0 = time.perf_counter()
        out = jax.block_until_ready(fn(*a, **kw))
        timings.append((label, time.perf_counter() - t0))
        return out

    rig = default_rig()
    scene = timed(
        "generate scene (incl. compile)",
        generate_scene,
        jax.random.PRNGKey(args.seed),
        rig,
        args.points,
        args.sigma,
        capacity=capacity,
    )
    result = timed(
        "associate, 1st call (compile + run)",
        associate,
        rig,
        scene.xy,
        scene.mask,
        method=config,
        sigma=sigma_arg,
    )
    result = timed(
        "associate, 2nd call (warm)",
        associate,
        rig,
        scene.xy,
        scene.mask,
        method=config,
        sigma=sigma_arg,
    )
    metrics = timed("metrics (incl. compile)", jit(scene_metrics), rig, result, scene)

    mask = np.asarray(scene.mask)
    valid = np.asarray(result.valid)
    n_views = np.asarray(result.n_views)[valid]
    n_det = int(mask.sum())
    n_inst = int(scene.num_points)
    n_unassigned = int(metrics.num_unassigned)
    M = rig.num_views
    w, h = IMAGE_SIZE

    lines = [
        f"C-DOG demo: method {args.method}, seed {args.seed}",
        "",
        f"Rig     built-in synthetic rig, {M} views, {w}×{h} px",
        f"Scene   {n_inst} points, {n_det} detections ({n_det / max(n_inst, 1):.1f} views per point), "
        f"σ = {args.sigma:g} px, capacity P = {capacity}",
        f"Used    σ = {float(result.sigma_px):.3f} px ({'estimated' if args.sigma_auto else 'given'}), "
        f"τ = {float(result.tau_px):.3f} px",
        f"Groups  {int(result.num_groups)} (ground truth: {int(metrics.num_gt_groups)} points seen in >= 2 views)",
        f"Unassigned detections  {n_unassigned} of {n_det}",
        "",
        "Views per group:",
    ]
    if n_views.size:
        counts = np.bincount(n_views, minlength=M + 1)
        top = int(counts.max())
        for k in range(2, M + 1):
            if counts[k]:
                bar = "█" * max(1, round(30 * counts[k] / top))
                lines.append(f"  {k:>2} views  {bar} {counts[k]}")
    else:
        lines.append("  (no groups)")

    values = {field: float(getattr(metrics, field)) for field, *_ in _METRIC_ROWS}
    lines += ["", "Metrics (this scene; definitions in docs/BENCHMARK.md §2):"]
    for field, name, fmt, note in _METRIC_ROWS:
        shown = format(values[field], fmt) if np.isfinite(values[field]) else "n/a"
        if field in ("err3d", "bpe_px") and int(metrics.num_err_groups) == 0:
            shown = "n/a"
        lines.append(f"  {name:<6} {shown:>8}   {note}")

    t0 = time.perf_counter()
    caption = "vs ground truth:   " + "   ".join(
        f"{name} {values[f]:{fmt}}" + (" px" if f == "bpe_px" else "")
        for f, name, fmt, _ in _METRIC_ROWS
    )
    write_output(
        args.out,
        "--out",
        lambda: plot_association(
            rig,
            scene.xy,
            scene.mask,
            result,
            points3d_gt=np.asarray(scene.points3d)[:n_inst],
            instance=scene.instance,
            title=caption,
            path=args.out,
        ),
    )
    timings.append(("figure (draw + save)", time.perf_counter() - t0))

    lines += ["", "Timings (wall clock, this process, JAX on " + jax.default_backend() + "):"]
    width = max(len(label) for label, _ in timings)
    lines += [f"  {label:<{width}}  {_seconds(s):>9}" for label, s in timings]
    lines += ["", f"Figure  {args.out}"]
    if args.save_scene is not None:
        write_output(
            args.save_scene,
            "--save-scene",
            lambda: _save_scene(args.save_scene, rig, scene, args.sigma, args.seed),
        )
        files = ", ".join(os.path.join(args.save_scene, name) for name in _SCENE_FILES)
        lines += [
            f"Scene   {files}",
            f"        try: cdog-jax associate --rig {os.path.join(args.save_scene, 'rig.json')} "
            f"--points {os.path.join(args.save_scene, 'detections.json')} --out groups.json",
        ]
    _emit(lines)
    return 0
