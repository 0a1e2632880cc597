"""Small accuracy grid for both presets on the built-in rig.

Question: how do ``paper()`` and ``reference()`` score (docs/BENCHMARK.md §2) at σ ∈ {0, 1, 3, 5} on a
few scenes of 10, 40 and 130 points? Usage: ``python experiments/small_grid.py [--scenes 5]``.
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np

import cdog_jax
from cdog_jax.metrics import mean_metrics, scene_metrics
from cdog_jax.synthetic import default_rig, generate_scenes

COLUMNS = ("g_f1", "mp_f1", "pg_p", "pg_r", "pg_f1", "err3d", "bpe_px")


def run(sigmas=(0.0, 1.0, 3.0, 5.0), counts=(10, 40, 130), scenes=5, seed=0, capacity=130):
    rig = default_rig()
    presets = {
        "paper": cdog_jax.Config.paper(),
        "extended": cdog_jax.Config.extended(),
        "reference": cdog_jax.Config.reference(),
    }
    score = jax.jit(jax.vmap(scene_metrics, in_axes=(None, 0, 0)))
    rows = []
    for sigma in sigmas:
        n = np.repeat(np.asarray(counts), scenes)
        batch = generate_scenes(
            jax.random.PRNGKey(seed),
            rig,
            jnp.asarray(n, jnp.int32),
            jnp.full(n.shape, sigma, jnp.float32),
            capacity=capacity,
        )
        for name, cfg in presets.items():
            t0 = time.perf_counter()
            res = cdog_jax.associate_batch(
                rig, batch.xy, batch.mask, method=cfg, sigma=sigma, batch_size=8
            )
            jax.block_until_ready(res)
            elapsed = time.perf_counter() - t0
            means = mean_metrics(score(rig, res, batch))
            rows.append((sigma, name, means, elapsed / len(n)))
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--scenes", type=int, default=5)
    parser.add_argument("--counts", type=int, nargs="+", default=[10, 40, 130])
    parser.add_argument("--sigmas", type=float, nargs="+", default=[0.0, 1.0, 3.0, 5.0])
    args = parser.parse_args(argv)
    rows = run(sigmas=args.sigmas, counts=args.counts, scenes=args.scenes)
    print("| σ (px) | preset | " + " | ".join(COLUMNS) + " | s/scene (first call incl. compile) |")
    print("|" + "---|" * (len(COLUMNS) + 3))
    for sigma, name, m, t in rows:
        print(
            f"| {sigma:g} | {name} | "
            + " | ".join(f"{m[c]:.3f}" for c in COLUMNS)
            + f" | {t:.3f} |"
        )


if __name__ == "__main__":
    main()
