"""``cdog-jax calibrate``: recover a drifted calibration of the built-in rig from detections
(the experiment is :mod:`cdog_jax.calibration`'s ``_drift_experiment.py``): the before →
after table, and the convergence figure."""

from __future__ import annotations

import argparse
import math

import numpy as np

from ._common import (
    _FIGURE_EXTENSIONS,
    _nonnegative_float,
    _positive_int,
    check_sigma_fits,
    seed_int,
)
from ._paths import check_output, write_output


def format_table(rows: list[dict]) -> str:
    """The before → after table (markdown)."""
    out = [
        "| level (rot°, shift, focal) | rotation err (°) | centre err (scene units) | focal err (%) "
        "| median BPE (px²) | PG-F1 (truth) | time warm / compile (s) |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lv = r["level"]
        out.append(
            f"| {lv.name} ({lv.rotation_deg:g}°, {100 * lv.translation_frac:g} %, {100 * lv.focal_frac:g} %) "
            f"| {r['rotation_deg'][0]:.3f} → {r['rotation_deg'][1]:.4f} "
            f"| {r['center'][0]:.4f} → {r['center'][1]:.5f} "
            f"| {r['focal_pct'][0]:.2f} → {r['focal_pct'][1]:.3f} "
            f"| {r['bpe'][0]:.1f} → {r['bpe'][1]:.2f} "
            f"| {r['pg_f1'][0]:.3f} → {r['pg_f1'][1]:.3f} ({r['pg_f1_truth']:.3f}) "
            + (
                f"| first call {r['first_s']:.1f} |"
                if np.isnan(r["warm_s"])
                else f"| {r['warm_s']:.2f} / "
                + ("–" if np.isnan(r["compile_s"]) else f"{r['compile_s']:.1f}")
                + " |"
            )
        )
    return "\n".join(out)


_DESCRIPTION = (
    "Recover a drifted calibration of the built-in rig from detections alone. Every camera is "
    "perturbed (rotated, moved, focal length scaled); detections are generated with the true "
    "cameras; association and a joint camera + point fit then alternate, starting from the "
    "perturbed cameras: first on sparse frames (2 points each) with a wide epipolar gate that "
    "shrinks every round, then on dense scenes with σ estimated. Prints the rotation, centre "
    "and focal errors against the truth, the BPE and PG-F1 before and after, and writes a "
    "figure of the BPE per round. The level 'none' starts at the truth: its errors are the "
    "floor. See docs/ALGORITHM.md and docs/GUIDE.md, 'Differentiating through cameras'."
)


def add_parser(subparsers) -> None:
    """Declare ``calibrate`` and its flags."""
    p = subparsers.add_parser(
        "calibrate",
        help="refine a perturbed built-in rig from detections",
        description=_DESCRIPTION,
    )
    p.add_argument(
        "--quick",
        action="store_true",
        help="one level (large), 2 scenes of 30 points, 16 wand frames, 2 + 1 rounds, no timing",
    )
    p.add_argument("--scenes", type=_positive_int, default=4, help="dense scenes (fine stage)")
    p.add_argument("--points", type=_positive_int, default=60, help="points per dense scene")
    p.add_argument(
        "--wand-frames", type=_positive_int, default=48, help="sparse frames (coarse stage)"
    )
    p.add_argument("--wand-points", type=_positive_int, default=2, help="points per sparse frame")
    p.add_argument("--sigma", type=_nonnegative_float, default=1.0, help="detection noise σ (px)")
    # Fine rounds: all but the last refine the poses only; the last frees the focal lengths too.
    p.add_argument(
        "--rounds",
        type=_positive_int,
        default=3,
        help="fine rounds (after one coarse round per gate)",
    )
    p.add_argument("--seed", type=seed_int, default=0)
    p.add_argument(
        "--out", default="calibration.png", help="convergence figure, .png/.pdf/.svg/.jpg"
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the experiment, print the table, write the figure; returns the exit code."""
    # The experiment needs optimistix, a large import, and the synthetic scenes: loaded when
    # the command runs.
    from ..calibration._drift_experiment import COARSE_GATES_PX, LEVELS, NO_DRIFT, run_experiment
    from ..synthetic import IMAGE_SIZE

    check_output(str(args.out), "--out", _FIGURE_EXTENSIONS, {})
    check_sigma_fits(
        args.sigma,
        math.hypot(*IMAGE_SIZE),
        f"the built-in rig ({IMAGE_SIZE[0]}×{IMAGE_SIZE[1]} px)",
    )
    if args.quick:
        levels, scenes, points, rounds, frames, gates, timing = (
            (LEVELS[2],),
            2,
            30,
            1,
            16,
            (120.0, 30.0),
            0,
        )
    else:
        levels, scenes, points, rounds, frames, gates, timing = (
            (NO_DRIFT, *LEVELS),
            args.scenes,
            args.points,
            args.rounds,
            args.wand_frames,
            COARSE_GATES_PX,
            3,
        )
    gate_text = " → ".join(f"{g:g}" for g in gates)
    print(
        f"Built-in rig, σ = {args.sigma:g} px. Coarse: {frames} frames × {args.wand_points} points, gate {gate_text} px. "
        f"Fine: {scenes} scenes × {points} points, {rounds} rounds.",
        flush=True,
    )
    rows = run_experiment(
        levels,
        scenes=scenes,
        points=points,
        sigma=args.sigma,
        rounds=rounds,
        wand_frames=frames,
        wand_points=args.wand_points,
        gates_px=gates,
        seed=args.seed,
        timing_runs=timing,
    )
    print(format_table(rows))
    from ..viz._calibration_plot import convergence_figure  # matplotlib's figure, on first use

    write_output(str(args.out), "--out", lambda: convergence_figure(rows, str(args.out)))
    print(f"Figure: {args.out}")
    return 0
