"""``cdog-jax calibrate``: recover a drifted calibration of the built-in rig from detections.

The experiment (issue 4, item 4), also run by ``experiments/calibrate.py``: for each
perturbation level, every view of the built-in rig is perturbed (rotation about a random
axis, camera centre moved, focal lengths scaled), scenes are generated with the *true* rig,
and ``calibrate`` (``cdog_jax/refine/_calibration.py``) alternates association
(``Config.extended`` with σ estimated, since a wrong rig inflates the epipolar distances far
beyond the detector noise) and joint camera + point refinement (Huber loss), starting from
the perturbed rig. Reported before and after: rotation, centre
and focal errors against the truth after a similarity alignment (the refinement fixes the
gauge differently from the truth), the BPE, and PG-F1 of associating with the given σ and
the rig before vs after. A figure shows the BPE per round.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import jax
import jax.numpy as jnp
import numpy as np

from ._config import Config
from .geometry._camera import Rig
from .geometry._parameters import so3_exp


@dataclasses.dataclass(frozen=True)
class Perturbation:
    """A calibration drift: rotation angle (degrees), centre shift (fraction of the mean
    camera-to-scene distance) and focal change (fraction), each the RMS over views."""

    name: str
    rotation_deg: float
    translation_frac: float
    focal_frac: float


LEVELS = (
    Perturbation("small", 0.25, 0.005, 0.005),
    Perturbation("medium", 0.5, 0.01, 0.01),
    Perturbation("large", 1.0, 0.02, 0.02),
)


def perturb_rig(key: jax.Array, rig: Rig, level: Perturbation, scene_center) -> Rig:
    """``rig`` with every view perturbed at ``level``: a rotation of ``N(0, θ²)`` degrees per
    axis component (so ``θ`` RMS per component), a centre shift of ``N(0, (f·d)²)`` per
    coordinate (``d`` = mean camera distance to ``scene_center (3,)``), focal lengths scaled
    by ``1 + N(0, f²)`` (fx and fy alike). ``K, R (M, 3, 3)``, ``t (M, 3)``."""
    M = rig.num_views
    k_rot, k_center, k_focal = jax.random.split(key, 3)
    dtype = rig.K.dtype
    w = jnp.deg2rad(level.rotation_deg) * jax.random.normal(k_rot, (M, 3), dtype)
    R = jnp.einsum("mij,mjk->mik", so3_exp(w), rig.R)
    centers = rig.centers
    distance = jnp.mean(jnp.linalg.norm(centers - jnp.asarray(scene_center, dtype)[None, :], axis=-1))
    centers = centers + level.translation_frac * distance * jax.random.normal(k_center, (M, 3), dtype)
    t = -jnp.einsum("mij,mj->mi", R, centers)
    scale = 1.0 + level.focal_frac * jax.random.normal(k_focal, (M,), dtype)
    K = rig.K.at[:, 0, 0].multiply(scale).at[:, 1, 1].multiply(scale)
    return Rig(K, R, t)


def run_experiment(
    levels=LEVELS,
    *,
    scenes: int = 4,
    points: int = 60,
    sigma: float = 1.0,
    rounds: int = 4,
    seed: int = 0,
    timing_runs: int = 3,
) -> list[dict]:
    """One row per level: errors, BPE and PG-F1 before and after, the BPE history per round,
    and the time of one (jitted) calibration, warm median and compile."""
    from ._pipeline import associate_traced
    from .metrics._scores import scene_metrics
    from .refine._calibration import calibrate, rig_errors
    from .synthetic import DEFAULT_BOX, default_rig, generate_scenes

    truth = default_rig()
    key_scenes, key_perturb = jax.random.split(jax.random.PRNGKey(seed))
    batch = generate_scenes(
        key_scenes,
        truth,
        jnp.full((scenes,), points, jnp.int32),
        jnp.full((scenes,), sigma, truth.K.dtype),
        capacity=points,
    )
    paper = Config.paper()
    # Association inside the calibration: σ estimated (the drift inflates epipolar distances),
    # extended() to keep 2-view points, Huber so that wrong members of early rounds pull less.
    inside = Config.extended(sigma_mode="auto")
    th_given = paper.thresholds(sigma)
    th_auto = inside.thresholds(0.0)
    static = inside.structure()

    @jax.jit
    def run(rig):
        # Extrinsics first, intrinsics last: with focal lengths free from the start, wrong
        # early associations let focal length trade against depth and the fit drifts away.
        kwargs = dict(thresholds=th_auto, config=static, loss="huber")
        rig, first = calibrate(rig, batch.xy, batch.mask, rounds=rounds - 1, refine_intrinsics=False, **kwargs)
        rig, last = calibrate(rig, batch.xy, batch.mask, rounds=1, refine_intrinsics=True, **kwargs)
        bpe = jnp.concatenate([first.bpe_after, last.bpe_after])
        return rig, first.bpe_before[0], bpe

    @jax.jit
    def pg_f1(rig):
        def one(xy, mask, scene):
            res = associate_traced(rig, xy, mask, th_given, paper.structure())
            return scene_metrics(rig, res, scene).pg_f1

        return jnp.mean(jax.vmap(one)(batch.xy, batch.mask, batch))

    center = np.mean(np.asarray(DEFAULT_BOX), axis=0)
    pg_f1_truth = float(pg_f1(truth))
    rows = []
    for i, level in enumerate(levels):
        start = perturb_rig(jax.random.fold_in(key_perturb, i), truth, level, center)
        t0 = time.perf_counter()
        refined, bpe_start, bpe_rounds = jax.block_until_ready(run(start))
        first = time.perf_counter() - t0
        times = []
        for _ in range(timing_runs):
            t0 = time.perf_counter()
            jax.block_until_ready(run(start))
            times.append(time.perf_counter() - t0)
        warm = float(np.median(times))
        before, after = rig_errors(start, truth), rig_errors(refined, truth)
        rows.append(
            dict(
                level=level,
                rotation_deg=(float(jnp.mean(before.rotation_deg)), float(jnp.mean(after.rotation_deg))),
                center=(float(jnp.mean(before.center)), float(jnp.mean(after.center))),
                focal_pct=(100 * float(jnp.mean(jnp.abs(before.focal_rel))), 100 * float(jnp.mean(jnp.abs(after.focal_rel)))),
                bpe=(float(bpe_start), float(bpe_rounds[-1])),
                pg_f1=(float(pg_f1(start)), float(pg_f1(refined))),
                pg_f1_truth=pg_f1_truth,
                bpe_rounds=np.asarray(bpe_rounds),
                bpe_start=float(bpe_start),
                warm_s=warm,
                compile_s=first - warm if i == 0 else float("nan"),  # compiled once, for level 0
            )
        )
    return rows


def format_table(rows: list[dict]) -> str:
    """The before → after table (markdown)."""
    out = [
        "| level (rot°, shift, focal) | rotation err (°) | centre err (scene units) | focal err (%) "
        "| BPE (px²) | PG-F1 (truth) | time warm / compile (s) |",
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
            f"| {r['warm_s']:.2f} / " + ("–" if np.isnan(r["compile_s"]) else f"{r['compile_s']:.1f}") + " |"
        )
    return "\n".join(out)


def convergence_figure(rows: list[dict], path: str) -> str:
    """BPE (px², log scale) at the start and after each round, one line per level."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.0), constrained_layout=True)
    for r in rows:
        values = np.concatenate([[r["bpe_start"]], r["bpe_rounds"]])
        lv = r["level"]
        ax.plot(np.arange(values.size), values, marker="o", label=f"{lv.name}: {lv.rotation_deg:g}°, {100 * lv.focal_frac:g} %")
    ax.set_yscale("log")
    ax.set_xlabel("round (association + joint refinement)")
    ax.set_ylabel("mean back-projection error (px², log)")
    ax.set_title("Camera refinement from a drifted built-in rig")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(title="perturbation")
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def add_parser(subparsers) -> None:
    """Declare ``calibrate`` and its flags."""
    p = subparsers.add_parser("calibrate", help="refine a perturbed built-in rig from detections", description=__doc__)
    p.add_argument("--quick", action="store_true", help="one level (medium), 2 scenes of 30 points, 2 rounds")
    # rounds: all but the last refine the poses only; the last frees the focal lengths too.
    p.add_argument("--scenes", type=int, default=4)
    p.add_argument("--points", type=int, default=60)
    p.add_argument("--sigma", type=float, default=1.0, help="detection noise σ (px)")
    p.add_argument("--rounds", type=int, default=4)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="calibration.png", help="convergence figure (PNG)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the experiment, print the table, write the figure; returns the exit code."""
    if args.quick:
        levels, scenes, points, rounds, timing = (LEVELS[1],), 2, 30, 2, 1
    else:
        levels, scenes, points, rounds, timing = LEVELS, args.scenes, args.points, args.rounds, 3
    print(f"Built-in rig, {scenes} scenes × {points} points, σ = {args.sigma:g} px, {rounds} rounds", flush=True)
    rows = run_experiment(levels, scenes=scenes, points=points, sigma=args.sigma, rounds=rounds, seed=args.seed, timing_runs=timing)
    print(format_table(rows))
    print(f"Figure: {convergence_figure(rows, str(args.out))}")
    return 0
