"""Per-stage ablation: how many ground-truth groups survive each stage of C-DOG?

Each row adds one stage to the previous one (cumulative configs): the epipolar graph with
view-uniqueness only, + δ-overlap pruning (Alg. 2), + IQR (Alg. 3), + the BPE jump filter
(§IV-E) = ``paper()``, then our additions: union adjacency, + recovery by reprojection,
+ regrouping = ``extended()``. Reported per σ (docs/BENCHMARK.md §2, mean over scenes): PG-R (share of
ground-truth groups found as a perfect group), PG-P, G-F1 and unassigned detections per
scene. Usage: ``python experiments/stage_ablation.py [--sigmas 1 3] [--scenes 2]
[--stages NAME,NAME]`` (``--stages`` picks rows by name; every row by default).
"""

from __future__ import annotations

import argparse
import json
import os

import numpy as np

from cdog_jax.benchmark import Grid, ablation_stages, sweep
from cdog_jax.synthetic import default_rig

STAGES = ablation_stages()
FIELDS = ("pg_r", "pg_p", "pg_f1", "g_f1", "num_unassigned")


def run(*, sigmas=(1.0, 3.0), counts=None, scenes=2, seed=100, stages=None):
    counts = counts or Grid.paper().counts
    grid = Grid(sigmas=tuple(sigmas), counts=tuple(counts), scenes=scenes, seed=seed)
    methods = STAGES if stages is None else {name: STAGES[name] for name in stages}
    res = sweep(default_rig(), grid, methods=methods, buckets=(max(counts),), timing=False)
    rows = []
    for sigma in grid.sigmas:
        where = np.isclose(res.sigma, sigma)
        for name in res.configs:
            m = res.metrics[name]
            rows.append(
                {"sigma": sigma, "stage": name, **{f: float(np.mean(m[f][where])) for f in FIELDS}}
            )
    return rows, res


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sigmas", type=float, nargs="+", default=[1.0, 3.0])
    parser.add_argument("--counts", type=int, nargs="+")
    parser.add_argument("--scenes", type=int, default=2)
    parser.add_argument(
        "--stages",
        default=None,
        help="comma-separated row names to run (default: every row): " + "; ".join(STAGES),
    )
    parser.add_argument("--out", default=None, help="write the rows as JSON here")
    args = parser.parse_args(argv)
    stages = None if args.stages is None else [s.strip() for s in args.stages.split(",")]
    unknown = [s for s in stages or () if s not in STAGES]
    if unknown:
        parser.error(f"--stages: no row named {unknown[0]!r}; the rows: {'; '.join(STAGES)}")
    rows, res = run(sigmas=args.sigmas, counts=args.counts, scenes=args.scenes, stages=stages)
    print(
        f"{res.num_scenes} scenes per stage; sweep {res.wall_s:.1f} s (compile {res.compile_s:.1f} s)"
    )
    print(
        "| σ (px) | stages | PG-R | PG-P | PG-F1 | G-F1 | unassigned / scene |\n|---|---|---|---|---|---|---|"
    )
    for r in rows:
        print(
            f"| {r['sigma']:g} | {r['stage']} | {r['pg_r']:.3f} | {r['pg_p']:.3f} | {r['pg_f1']:.3f} | {r['g_f1']:.3f} | {r['num_unassigned']:.1f} |"
        )
    if args.out:
        os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
        with open(args.out, "w") as f:
            json.dump(rows, f, indent=1)
    return rows


if __name__ == "__main__":
    main()
