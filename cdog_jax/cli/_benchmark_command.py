"""``cdog-jax benchmark``: the benchmark grid (docs/BENCHMARK.md) for several methods, tables and figures.

Runs :func:`~cdog_jax.benchmark.sweep` once (every method and scene, one compiled program per bucket),
prints the paper-style table at σ = 0, 1, 3, 5, saves the per-scene results (NPZ, CSV,
JSON) and writes the figures of :mod:`cdog_jax.viz` into ``--out``.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from ..benchmark._methods import DEFAULT_METHODS, METHODS
from ..io import load_rig
from ..io._errors import InputError
from ..io._rig_files import FORMATS
from ._associate_command import _RIG_FORMATS_TEXT
from ._common import _nonnegative_float, _nonnegative_int, _positive_int, seed_int
from ._paths import check_input, check_output_folder, input_files, write_output


def _method_list(text: str) -> tuple[str, ...]:
    """Names from ``a,b,c``; ``all`` is every named method that the compiled sweep runs
    (registered ones and the ablation; host methods, ``jittable`` False, are left out)."""
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    if names == ("all",):
        return tuple(n for n in METHODS if METHODS[n]().jittable)
    unknown = [n for n in names if n not in METHODS]
    if unknown or not names:
        raise argparse.ArgumentTypeError(
            f"methods must be 'all' or a comma list of {', '.join(METHODS)}; got {text!r}"
        )
    return names


_DESCRIPTION = (
    "Generate, associate and score a grid of synthetic scenes (noise σ × point count × scenes; "
    "docs/BENCHMARK.md) for several methods in one compiled program per bucket, print the paper-style table "
    "at σ = 0, 1, 3, 5, save the per-scene results (NPZ, CSV, JSON) and write figures (heat "
    "maps, score surfaces, metrics against σ, time against point count) into --out. The full "
    "grid is 4,410 scenes; --quick runs a small one in under a minute. On a CPU the scenes "
    "run on every core at once (JAX shows one CPU device per core; XLA_FLAGS="
    "--xla_force_host_platform_device_count=N chooses another count)."
)


def add_parser(subparsers) -> None:
    """Declare ``benchmark`` and its flags."""
    p = subparsers.add_parser(
        "benchmark",
        help="run the noise x density benchmark grid, print tables, write figures",
        description=_DESCRIPTION,
    )
    p.add_argument(
        "--quick", action="store_true", help="tiny grid (σ 0,1,3,5 × counts 5,20,60 × 2 scenes)"
    )
    p.add_argument(
        "--out", default="benchmark_results", help="output folder (default: %(default)s)"
    )
    p.add_argument(
        "--methods",
        type=_method_list,
        default=DEFAULT_METHODS,
        help="'all' or a comma list of the named methods (default "
        + ",".join(DEFAULT_METHODS)
        + "); registered: "
        + ", ".join(METHODS),
    )
    p.add_argument(
        "--sigmas",
        type=_nonnegative_float,
        nargs="+",
        help="noise levels σ in px (default: the grid's)",
    )
    p.add_argument(
        "--counts", type=_positive_int, nargs="+", help="point counts (default: the grid's)"
    )
    p.add_argument("--scenes", type=_positive_int, help="scenes per (σ, count) cell")
    p.add_argument(
        "--views", type=_nonnegative_int, nargs="+", help="rig view indices to use (default: all)"
    )
    p.add_argument("--seed", type=seed_int, default=0, help="PRNG seed of the scenes (default 0)")
    p.add_argument(
        "--buckets",
        type=_positive_int,
        nargs="+",
        help="slot capacities (default: fitted to the counts)",
    )
    p.add_argument(
        "--rig", help="run on this rig instead of the built-in one: " + _RIG_FORMATS_TEXT
    )
    p.add_argument(
        "--rig-format",
        default="auto",
        choices=("auto", *FORMATS),
        help="rig file format (default: from the path)",
    )
    p.add_argument(
        "--box",
        type=float,
        nargs=6,
        metavar=("X0", "Y0", "Z0", "X1", "Y1", "Z1"),
        help="3D sampling box (scene units; default: the built-in rig's, or for --rig the region ≥ 2 views see)",
    )
    p.add_argument(
        "--image-size",
        type=_positive_int,
        nargs=2,
        metavar=("W", "H"),
        help="image size in px (default: the built-in rig's, or the rig file's, or guessed from K)",
    )
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.add_argument("--no-timing", action="store_true", help="skip the per-scene time estimates")
    p.add_argument(
        "--no-progress",
        action="store_true",
        help="no progress bar or per-bucket lines (e.g. for a log of several runs)",
    )
    p.set_defaults(func=run)


def _grid_from_args(args):
    # The benchmark's modules load when the command runs: the other commands never pay.
    from ..benchmark._grid import Grid

    grid = Grid.quick() if args.quick else Grid.paper()
    changes = {}
    if args.sigmas:
        changes["sigmas"] = tuple(args.sigmas)
    if args.counts:
        changes["counts"] = tuple(sorted(set(args.counts)))
    if args.scenes:
        changes["scenes"] = args.scenes
    if args.views:
        changes["views"] = tuple(args.views)
    changes["seed"] = args.seed
    return grid.replace(**changes)


def _buckets_for(counts, requested, quick: bool) -> tuple[int, ...]:
    """Slot capacities: as requested; one (compiles fastest) for ``--quick``; else a few
    (each bucket compiles the pipeline once more but saves padded work)."""
    if requested:
        return tuple(sorted(set(requested)))
    top = max(counts)
    if quick:
        return (top,)
    return tuple(b for b in (20, 50, 90) if b < top) + (top,)


def _scene_setup(args, grid):
    """``(rig, box, image_size, description)`` for the sweep: the built-in rig and box, or
    the rig file of ``--rig`` with the box the (selected) views see, unless ``--box``."""
    # The synthetic scenes' module loads only in the commands that make scenes.
    from ..synthetic import DEFAULT_BOX, IMAGE_SIZE, default_rig, visible_box
    from ..synthetic._box import intrinsics_image_size

    def check_views(rig, name):
        if grid.views is not None and max(grid.views) >= rig.num_views:
            raise InputError(
                f"--views {list(grid.views)} out of range for {name} ({rig.num_views} views)"
            )

    if not args.rig:
        image_size = tuple(args.image_size) if args.image_size else IMAGE_SIZE
        box = (tuple(args.box[:3]), tuple(args.box[3:])) if args.box else DEFAULT_BOX
        rig = default_rig()
        check_views(rig, "the built-in rig")
        return rig, box, image_size, "the built-in 10-view rig"

    # Far from its world's origin (UTM-like coordinates) the rig is centred on its cameras,
    # which float32 can hold; a --box given in the file's world moves with it.
    loaded = load_rig(args.rig, format=args.rig_format, origin="auto")
    rig = loaded.rig
    origin = np.zeros(3) if loaded.origin is None else loaded.origin
    check_views(rig, args.rig)
    if args.image_size:
        image_size, source = tuple(args.image_size), "--image-size"
    elif loaded.image_size is not None:
        image_size, source = loaded.image_size, "the rig file"
    else:
        image_size, source = intrinsics_image_size(rig.K), "guessed from K's principal points"
    if args.box:
        box = tuple(
            tuple(np.asarray(corner, np.float64) - origin)
            for corner in (args.box[:3], args.box[3:])
        )
        box_source = "--box"
    else:
        used = rig if grid.views is None else rig.select(grid.views)
        box, box_source = visible_box(used, image_size), "the region ≥ 2 of the views see"
    lo, hi = (", ".join(f"{v:.3g}" for v in np.asarray(corner) + origin) for corner in box)
    text = (
        f"{args.rig} ({rig.num_views} views); image {image_size[0]}×{image_size[1]} px ({source}); "
        f"box ({lo}) – ({hi}) ({box_source})"
    )
    if loaded.origin is not None:
        x, y, z = loaded.origin
        text += (
            f"\n  note: the cameras lie far from the rig's world origin; the scenes are made and "
            f"associated about their mean centre ({x:.3f}, {y:.3f}, {z:.3f}), and the rig and "
            "box written with the results are about it"
        )
    return rig, box, image_size, text


def _check_paths(args) -> None:
    """The rig exists; ``--out`` is (or can be made) a writable folder whose files are
    not the rig's. Before any work."""
    inputs = {}
    if args.rig:
        check_input(args.rig, "--rig", kind="any")
        inputs["--rig"] = input_files(args.rig)
    names = [
        "results.npz",
        "results.csv",
        "results.json",
        "metrics_vs_sigma.png",
        "time_vs_count.png",
    ]
    names += [f"{kind}_{name}.png" for name in args.methods for kind in ("heatmaps", "surfaces")]
    check_output_folder(args.out, "--out", names, inputs)


def run(args: argparse.Namespace) -> int:
    """Run the benchmark; returns the exit code."""
    # The sweep, its figures and the progress bar load when the command runs: the other
    # commands and --help never pay for them.
    from .. import viz as figures
    from .._runtime.progress import interactive, sweep_bar
    from ..benchmark._cpu_cores import use_cpu_cores
    from ..benchmark._io import save_results, summary_table
    from ..benchmark._sweep import print_progress, sweep

    use_cpu_cores()  # before JAX's first operation; the sweep then shards its scenes over the cores
    _check_paths(args)
    grid = _grid_from_args(args)
    configs = {name: METHODS[name]() for name in args.methods}
    buckets = _buckets_for(grid.counts, args.buckets, args.quick)
    rig, box, image_size, rig_text = _scene_setup(args, grid)
    print(f"Rig: {rig_text}")
    print(
        f"Grid: {len(grid.sigmas)} σ × {len(grid.counts)} counts × {grid.scenes} scenes = {grid.num_scenes} scenes; "
        f"methods: {', '.join(configs)}; buckets {buckets}",
        flush=True,
    )
    print(
        "Generating, associating and scoring every scene, one compiled program per bucket (compiling first) …",
        flush=True,
    )
    # A live bar in a terminal; in a log, one line per finished bucket.
    if args.no_progress:
        progress, close_bar = None, lambda: None
    else:
        progress, close_bar = (
            sweep_bar(grid.num_scenes) if interactive() else (print_progress, lambda: None)
        )
    t0 = time.perf_counter()
    try:
        result = sweep(
            rig,
            grid,
            methods=configs,
            buckets=buckets,
            box=box,
            image_size=image_size,
            timing=not args.no_timing,
            progress=progress,
        )
    finally:
        close_bar()
    total = time.perf_counter() - t0
    print(
        f"Done: sweep call {result.wall_s:.2f} s warm-equivalent (compile {result.compile_s:.2f} s), "
        f"timing estimates {result.timing_s:.2f} s, total {total:.2f} s on {result.device}",
        flush=True,
    )
    print()
    standard = [s for s in (0.0, 1.0, 3.0, 5.0) if any(abs(s - g) < 5e-4 for g in grid.sigmas)]
    print(summary_table(result, sigmas=standard if len(standard) >= 2 else grid.sigmas))
    print()

    write_output(
        args.out,
        "--out",
        lambda: (os.makedirs(args.out, exist_ok=True), save_results(result, args.out)),
    )
    print(f"Results: {args.out}/ (NPZ, CSV, JSON)")
    if not args.no_figures:
        write_output(args.out, "--out", lambda: _figures(figures, result, args))
        print(f"Figures: {args.out}/*.png")
    return 0


def _figures(figures, result, args) -> None:
    """The benchmark's PNG figures in ``args.out``."""
    from ..benchmark._grid import Grid  # loaded when the command runs (_grid_from_args)

    metrics = {name: result.metrics[name] for name in result.configs}
    for name in result.configs:
        figures.heatmaps(
            result.sigma,
            result.count,
            metrics,
            method=name,
            path=os.path.join(args.out, f"heatmaps_{name}.png"),
        )
        figures.surfaces(
            result.sigma,
            result.count,
            metrics,
            method=name,
            path=os.path.join(args.out, f"surfaces_{name}.png"),
        )
    full = Grid.paper()
    grid = result.grid
    full_grid = (grid.sigmas, grid.counts, grid.views) == (
        full.sigmas,
        full.counts,
        None,
    ) and grid.scenes >= full.scenes
    figures.metrics_vs_sigma(
        result.sigma,
        metrics,
        full_grid=full_grid,
        path=os.path.join(args.out, "metrics_vs_sigma.png"),
    )
    if not args.no_timing:
        figures.time_vs_count(
            result.count,
            result.time_s,
            capacity=result.capacity,
            path=os.path.join(args.out, "time_vs_count.png"),
        )
