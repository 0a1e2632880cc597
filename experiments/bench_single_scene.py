"""Single-scene speed on the built-in rig: compile time and warm wall time of ``associate``.

Question: how long does one scene take, cold (trace + compile + run) and warm, for 10, 40
and 130 points at σ = 1? Capacity P = point count. Warm time is the median of ``--runs``
calls timed with ``time.perf_counter`` around ``associate`` + ``block_until_ready``;
compile time = first call − warm median. Usage:
``python experiments/bench_single_scene.py [--runs 7]``.
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

import cdog_jax
from cdog_jax.synthetic import default_rig, generate_scene


def bench(counts=(10, 40, 130), sigma=1.0, runs=7):
    rig = default_rig()
    rows = []
    for preset in ("paper", "reference"):
        cfg = getattr(cdog_jax.Config, preset)()
        for n in counts:
            scene = generate_scene(jax.random.PRNGKey(n), rig, n, sigma, capacity=n)
            t0 = time.perf_counter()
            jax.block_until_ready(cdog_jax.associate(rig, scene.xy, scene.mask, config=cfg, sigma=sigma))
            first = time.perf_counter() - t0
            warm = []
            for _ in range(runs):
                t0 = time.perf_counter()
                jax.block_until_ready(cdog_jax.associate(rig, scene.xy, scene.mask, config=cfg, sigma=sigma))
                warm.append(time.perf_counter() - t0)
            w = float(np.median(warm))
            rows.append((preset, n, first - w, w))
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--runs", type=int, default=7)
    args = parser.parse_args(argv)
    print(f"JAX {jax.__version__} on {jax.default_backend()}")
    print("| preset | points | compile (s) | warm median (ms) |\n|---|---|---|---|")
    for preset, n, compile_s, warm_s in bench(runs=args.runs):
        print(f"| {preset} | {n} | {compile_s:.2f} | {1000 * warm_s:.1f} |")


if __name__ == "__main__":
    main()
