"""The drift-recovery experiment of ``cdog-jax calibrate`` (also run by
``experiments/calibrate.py``): recover a drifted calibration of the built-in rig from
detections alone. For each
perturbation level, every view of the built-in rig is perturbed (rotation about a random
axis, camera centre moved, focal lengths scaled), detections are generated with the *true*
rig, and ``calibrate`` (``_calibrate.py``) alternates association and
joint camera + point refinement (Huber loss), starting from the perturbed rig, in two stages:

1. coarse: sparse frames (a "wand": 2 points per frame, 48 frames) associated with a wide
   epipolar gate that shrinks every round (120 → 60 → 30 → 15 px), poses only. A drifted rig
   moves epipolar lines by tens of pixels; only sparse frames keep such a gate unambiguous.
2. fine: the dense scenes, associated with σ estimated (``Config.extended``), poses for
   ``rounds - 1`` rounds, then one round that frees the focal lengths as well (free focal
   lengths early trade against depth while associations are still wrong).

Reported before and after: rotation, centre and focal errors against the truth after a
similarity alignment (the refinement fixes the gauge differently from the truth), the BPE
of the dense scenes, and PG-F1 of associating them with the given σ and the rig before vs
after. A figure shows the BPE per round. The level "none" starts at the truth: its errors
are the estimator's own (noise and weakly observable directions), the floor for the others.
"""

from __future__ import annotations

import contextlib
import dataclasses
import time

import jax
import jax.numpy as jnp
import numpy as np

from .._runtime.progress import bar, compiling
from ..cdog._pipeline import Config, associate_traced
from ..geometry._camera import Rig
from ..geometry._parameters import so3_exp
from ..metrics._scores import scene_metrics
from ..synthetic import DEFAULT_BOX, default_rig, generate_scenes
from ._alignment import rig_errors
from ._calibrate import calibrate


@dataclasses.dataclass(frozen=True)
class Perturbation:
    """A calibration drift: rotation angle (degrees), centre shift (fraction of the mean
    camera-to-scene distance) and focal change (fraction), each the RMS over views."""

    name: str
    rotation_deg: float
    translation_frac: float
    focal_frac: float


NO_DRIFT = Perturbation("none", 0.0, 0.0, 0.0)
LEVELS = (
    Perturbation("small", 0.25, 0.005, 0.005),
    Perturbation("medium", 0.5, 0.01, 0.01),
    Perturbation("large", 1.0, 0.02, 0.02),
)
COARSE_GATES_PX = (120.0, 60.0, 30.0, 15.0)


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
    distance = jnp.mean(
        jnp.linalg.norm(centers - jnp.asarray(scene_center, dtype)[None, :], axis=-1)
    )
    centers = centers + level.translation_frac * distance * jax.random.normal(
        k_center, (M, 3), dtype
    )
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
    rounds: int = 3,
    wand_frames: int = 48,
    wand_points: int = 2,
    gates_px: tuple[float, ...] = COARSE_GATES_PX,
    seed: int = 0,
    timing_runs: int = 3,
) -> list[dict]:
    """One row per level: errors, BPE and PG-F1 before and after, the BPE history per round
    (coarse rounds on the wand frames, then fine rounds on the scenes), and the time of one
    (jitted) calibration, warm median and compile.

    ``scenes × points`` dense scenes and ``wand_frames × wand_points`` sparse frames are
    generated with the true rig at noise ``sigma`` (px); the coarse stage runs one round
    per gate in ``gates_px``, the fine stage ``rounds`` rounds (the last with free focal
    lengths)."""
    if rounds < 1 or not gates_px:
        raise ValueError(
            f"need rounds >= 1 and at least one coarse gate; got rounds={rounds}, gates={gates_px}"
        )
    truth = default_rig()
    dtype = truth.K.dtype
    key_scenes, key_perturb, key_wand = jax.random.split(jax.random.PRNGKey(seed), 3)

    def draw(key, count, num):
        return generate_scenes(
            key,
            truth,
            jnp.full((count,), num, jnp.int32),
            jnp.full((count,), sigma, dtype),
            capacity=num,
        )

    batch, wand = draw(key_scenes, scenes, points), draw(key_wand, wand_frames, wand_points)
    paper = Config.paper()
    th_given = paper.thresholds(sigma)
    # Coarse: the gate is tau_min (one entry per round) since it dominates alpha_tau·√2·σ;
    # recovery attaches within 1 gate (not 2) because the gate is already wide.
    coarse = Config.extended()
    th_coarse = coarse.thresholds(sigma)._replace(
        tau_min_px=np.asarray(gates_px, np.dtype(dtype)),
        recover_frac=np.asarray(1.0, np.dtype(dtype)),
    )
    # Fine: σ estimated from the detections (the drift left inflates epipolar distances).
    fine = Config.extended(sigma_mode="auto")
    th_fine = fine.thresholds(0.0)

    @jax.jit
    def run(rig):
        common = dict(loss="huber", refine_intrinsics=False)
        rig, h_coarse = calibrate(
            rig,
            wand.xy,
            wand.mask,
            thresholds=th_coarse,
            method=coarse.structure(),
            rounds=len(gates_px),
            **common,
        )
        kwargs = dict(thresholds=th_fine, method=fine.structure(), loss="huber")
        history = [h_coarse.rigs]
        if rounds > 1:
            rig, h_poses = calibrate(
                rig, batch.xy, batch.mask, rounds=rounds - 1, refine_intrinsics=False, **kwargs
            )
            history.append(h_poses.rigs)
        # Focal lengths last: freed early, they trade against depth while groups are wrong.
        rig, h_last = calibrate(
            rig, batch.xy, batch.mask, rounds=1, refine_intrinsics=True, **kwargs
        )
        history.append(h_last.rigs)
        per_round = jax.tree_util.tree_map(
            lambda *a: jnp.concatenate(a), *history
        )  # (rounds_total, M, ...)
        errors = jax.vmap(lambda r: rig_errors(r, truth))(per_round)
        return (
            rig,
            jnp.mean(errors.rotation_deg, axis=1),
            100 * jnp.mean(jnp.abs(errors.focal_rel), axis=1),
        )

    @jax.jit
    def scores(rig):
        """Mean PG-F1 of the dense scenes (``paper()``, the true σ), and their BPE (px²):
        the median over the groups that the fine stage's association finds with ``rig``
        (the median, because a few wrong groups of thousands of px² would dominate a mean)."""

        def one(xy, mask, scene):
            res = associate_traced(rig, xy, mask, th_given, paper.structure())
            found = associate_traced(rig, xy, mask, th_fine, fine.structure())
            return scene_metrics(rig, res, scene).pg_f1, jnp.where(found.valid, found.bpe, jnp.nan)

        pg_f1, bpe = jax.vmap(one)(batch.xy, batch.mask, batch)
        return jnp.mean(pg_f1), jnp.nanmedian(bpe)

    center = np.mean(np.asarray(DEFAULT_BOX), axis=0)
    with compiling("the scoring of the dense scenes (with its first run)"):
        pg_f1_truth = float(scores(truth)[0])
    rows = []
    levels_bar = bar(len(levels), "calibrate: drift levels", unit="level")
    for i, level in enumerate(levels):
        start = perturb_rig(jax.random.fold_in(key_perturb, i), truth, level, center)
        t0 = time.perf_counter()
        with (
            compiling("the calibration (with its first run)")
            if i == 0
            else contextlib.nullcontext()
        ):
            refined, rotation_rounds, focal_rounds = jax.block_until_ready(run(start))
        first = time.perf_counter() - t0
        times = []
        for _ in range(timing_runs):
            t0 = time.perf_counter()
            jax.block_until_ready(run(start))
            times.append(time.perf_counter() - t0)
        warm = float(np.median(times)) if times else float("nan")
        before, after = rig_errors(start, truth), rig_errors(refined, truth)
        (pg_before, bpe_before), (pg_after, bpe_after) = scores(start), scores(refined)
        rows.append(
            dict(
                level=level,
                rotation_deg=(
                    float(jnp.mean(before.rotation_deg)),
                    float(jnp.mean(after.rotation_deg)),
                ),
                center=(float(jnp.mean(before.center)), float(jnp.mean(after.center))),
                focal_pct=(
                    100 * float(jnp.mean(jnp.abs(before.focal_rel))),
                    100 * float(jnp.mean(jnp.abs(after.focal_rel))),
                ),
                bpe=(float(bpe_before), float(bpe_after)),
                pg_f1=(float(pg_before), float(pg_after)),
                pg_f1_truth=pg_f1_truth,
                rotation_rounds=np.asarray(rotation_rounds),
                focal_rounds=np.asarray(focal_rounds),
                coarse_rounds=len(gates_px),
                warm_s=warm,
                compile_s=first - warm if i == 0 else float("nan"),  # compiled once, for level 0
                first_s=first,
            )
        )
        levels_bar.update(1)
    levels_bar.close()
    return rows
