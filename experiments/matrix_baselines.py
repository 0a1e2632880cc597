"""Pair precision / recall and warm time of the matrix baselines (MatchEIG, matchSVT, spectral
clustering) on synthetic scenes of the built-in rig.

Question: how well do the spectral and low-rank baselines associate noise-free and noisy
scenes, and what does one scene cost on the CPU? A pair of detections is a true positive
when a method puts both in one group and they image one point; precision and recall are
pooled over all scenes. σ (px) is known to the methods; τ = max(2√2·σ, 1 px). Time per
scene is warm (compiled apart); on a shared CPU the minimum is the steadier figure.

    python experiments/matrix_baselines.py --views 10 --points 50 --scenes 20
"""

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np

from cdog_jax.baselines import MatchSVT, SpectralClustering, SpectralSync
from cdog_jax.geometry import epipolar_distances
from cdog_jax.synthetic import default_rig, generate_scenes

METHODS = {
    "MatchEIG": SpectralSync(),
    "matchSVT": MatchSVT(),
    "spectral clustering": SpectralClustering(),
}


def runner(method, rig):
    @jax.jit
    def run(xy, mask, sigma):
        d = epipolar_distances(rig, xy, mask)
        tau = jnp.maximum(2.0 * jnp.sqrt(jnp.asarray(2.0, sigma.dtype)) * sigma, 1.0)
        return method.group_table(
            rig, xy, mask, d, sigma, tau, method.thresholds(sigma, dtype=rig.K.dtype)
        )

    return run


def pair_counts(groups, valid, instance):
    """(true positive, predicted, true) same-point pairs of one scene."""
    label = np.full(instance.shape, -1)
    for g in np.flatnonzero(valid):
        for m, s in enumerate(groups[g]):
            if s >= 0:
                label[m, s] = g
    lab, inst = label.reshape(-1), instance.reshape(-1)
    upper = np.triu(np.ones((lab.size, lab.size), bool), 1)
    pred = upper & (lab[:, None] == lab[None, :]) & (lab[:, None] >= 0)
    true = upper & (inst[:, None] == inst[None, :]) & (inst[:, None] >= 0)
    return int((pred & true).sum()), int(pred.sum()), int(true.sum())


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", type=int, default=10)
    parser.add_argument("--points", type=int, default=50)
    parser.add_argument("--scenes", type=int, default=20)
    parser.add_argument("--sigmas", type=float, nargs="+", default=[0.0, 1.0, 3.0])
    parser.add_argument("--methods", nargs="+", default=list(METHODS))
    args = parser.parse_args()
    rig = default_rig().select(range(args.views))
    print(f"{args.views} views, {args.points} points, {args.scenes} scenes per σ")
    print("| method | σ (px) | pair precision | pair recall | warm s/scene (median) | (min) |")
    print("|---|---|---|---|---|---|")
    for name in args.methods:
        run = runner(METHODS[name], rig)
        for sigma in args.sigmas:
            scenes = generate_scenes(
                jax.random.PRNGKey(0),
                rig,
                jnp.full((args.scenes,), args.points, jnp.int32),
                jnp.full((args.scenes,), sigma),
                capacity=args.points,
            )
            sig = jnp.asarray(sigma, rig.K.dtype)
            jax.block_until_ready(run(scenes.xy[0], scenes.mask[0], sig))  # compile apart
            tp = pred = true = 0
            times = []
            for b in range(args.scenes):
                start = time.perf_counter()
                groups, valid, _ = jax.block_until_ready(run(scenes.xy[b], scenes.mask[b], sig))
                times.append(time.perf_counter() - start)
                counts = pair_counts(
                    np.asarray(groups), np.asarray(valid), np.asarray(scenes.instance[b])
                )
                tp, pred, true = tp + counts[0], pred + counts[1], true + counts[2]
            print(
                f"| {name} | {sigma:g} | {tp / max(pred, 1):.4f} | {tp / max(true, 1):.4f} | {np.median(times):.3f} | {np.min(times):.3f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
