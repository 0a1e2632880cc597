"""Views ablation at σ = 3 px (paper Table I).

Question: how does PG-F1 (and mP-F1, G-F1) of ``paper()`` and ``extended()`` change with
the number of views k = 2 … 10, when the k views are drawn at random from the built-in
10-camera rig (``cdog_jax.synthetic.default_rig()``)? The paper's Table I reports PG-F1 at
σ = 3 for 2 … 10 views: 0.766, 0.726, 0.562, 0.601, 0.668, 0.685, 0.719, 0.747, 0.761.

Method: for every k, ``--subsets`` subsets of k distinct views are drawn with a NumPy RNG
(``--seed``); the 10-view "subset" is the whole rig, so repeats are skipped there. Each
subset runs one :func:`cdog_jax.benchmark.sweep` on ``Grid(sigmas=(3.0,), counts, scenes,
views=subset)`` with both methods, ``timing=False`` and a single capacity bucket (the
largest count). Per-scene metrics of all subsets of one k are pooled and averaged by the rule of
:func:`cdog_jax.metrics.mean_metrics` for scores (plain means over all scenes).

How the views subset enters the scenes: ``sweep`` replaces the rig by
``rig.select(grid.views)`` *before* the scenes are generated, so ``generate_scene`` decides
visibility on the selected views only: a point is kept only when it projects inside the
image of ≥ 2 of the *selected* views, and its detections exist in those views only. Scene
keys depend on (σ, count, scene index, grid seed) alone, not on the views, so every subset
draws the same candidate 3D points and keeps the first ``count`` of them visible in ≥ 2 of
its views (a paired design across k). If fewer than ``count`` of the ``4 × capacity``
candidates qualify (possible for narrow 2-view subsets), the scene has fewer points; the
JSON records the mean actual point count per k.

Usage::

    python experiments/views_ablation.py [--counts 10 30 60] [--scenes 10] [--subsets 8]
        [--views-range 2 10] [--seed 0] [--out experiments/figures]

Writes ``views_ablation.json`` and ``views_ablation.png`` into ``--out`` and prints a
Markdown table.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

from cdog_jax import Config
from cdog_jax.benchmark import Grid, sweep
from cdog_jax.benchmark import metric_fields
from cdog_jax.viz import PAPER_VIEWS_PG_F1, views_ablation
from cdog_jax.synthetic import default_rig

SIGMA = 3.0
FIELDS = ("pg_f1", "mp_f1", "g_f1")
PAPER_TABLE_I = dict(zip(range(2, 2 + len(PAPER_VIEWS_PG_F1)), PAPER_VIEWS_PG_F1))


def draw_subsets(num_views: int, k: int, subsets: int, rng: np.random.Generator) -> list[tuple[int, ...]]:
    """``subsets`` distinct sorted k-subsets of ``range(num_views)`` (fewer when not possible)."""
    from math import comb

    want = min(subsets, comb(num_views, k))
    out: list[tuple[int, ...]] = []
    while len(out) < want:
        s = tuple(sorted(int(v) for v in rng.choice(num_views, size=k, replace=False)))
        if s not in out:
            out.append(s)
    return out


def run(*, views_range=(2, 10), counts=(10, 30, 60), scenes=10, subsets=8, seed=0, grid_seed=0, log=print):
    """Run the ablation; returns a JSON-able dict of the per-k means and run details."""
    rig = default_rig()
    configs = {"paper": Config.paper(), "extended": Config.extended()}
    rng = np.random.default_rng(seed)
    counts = tuple(int(c) for c in counts)
    ks = list(range(int(views_range[0]), int(views_range[1]) + 1))
    if ks[0] < 2 or ks[-1] > rig.num_views:
        raise ValueError(f"views range must lie in [2, {rig.num_views}]; got {views_range}")
    rows, per_scene_views, per_scene = [], [], {name: {f: [] for f in FIELDS} for name in configs}
    t_all = time.perf_counter()
    for k in ks:
        t0 = time.perf_counter()
        subs = draw_subsets(rig.num_views, k, subsets, rng)
        pooled = {name: [] for name in configs}
        num_points, compile_s = [], 0.0
        for sub in subs:
            grid = Grid(sigmas=(SIGMA,), counts=counts, scenes=scenes, seed=grid_seed, views=sub)
            res = sweep(rig, grid, configs=configs, buckets=(max(counts),), timing=False)
            compile_s += res.compile_s
            num_points.append(res.num_points)
            for name in configs:
                pooled[name].append(res.metrics[name])
        row = {"views": k, "subsets": [list(s) for s in subs], "num_scenes": 0,
               "mean_points": float(np.mean(np.concatenate(num_points))),
               "mean_requested": float(np.mean(np.tile(np.repeat(counts, scenes), len(subs)))),
               "paper_table_i_pg_f1": PAPER_TABLE_I.get(k), "seconds": 0.0, "compile_s": compile_s}
        for name in configs:
            fields = {f: np.concatenate([m[f] for m in pooled[name]]) for f in metric_fields()}
            # mean_metrics' rule for scores (a plain mean over all scenes, zeros included);
            # Metrics itself is not built here, its runtime type check wants jax arrays.
            means = {f: float(np.mean(fields[f].astype(np.float64))) for f in fields}
            means["num_scenes"] = float(fields["pg_f1"].size)
            row[name] = {f: means[f] for f in ("pg_f1", "pg_p", "pg_r", "mp_f1", "g_f1")}
            row["num_scenes"] = int(means["num_scenes"])
            for f in FIELDS:
                per_scene[name][f].append(fields[f])
        per_scene_views.append(np.full(row["num_scenes"], k))
        row["seconds"] = time.perf_counter() - t0
        rows.append(row)
        log(f"k={k}: {len(subs)} subset(s), {row['num_scenes']} scenes, {row['seconds']:.1f} s "
            f"(compile {compile_s:.1f} s); PG-F1 paper {row['paper']['pg_f1']:.3f}, "
            f"extended {row['extended']['pg_f1']:.3f}")
    return {
        "sigma_px": SIGMA,
        "counts": list(counts),
        "scenes_per_cell": scenes,
        "subsets_per_k": subsets,
        "seed": seed,
        "grid_seed": grid_seed,
        "methods": list(configs),
        "rows": rows,
        "total_seconds": time.perf_counter() - t_all,
        "_per_scene": {"views": np.concatenate(per_scene_views),
                       "metrics": {n: {f: np.concatenate(v) for f, v in d.items()} for n, d in per_scene.items()}},
    }


def markdown_table(out: dict) -> str:
    methods = out["methods"]
    head = ["views"] + [f"{m} {lab}" for m in methods for lab in ("PG-F1", "mP-F1", "G-F1")] + ["paper Table I PG-F1"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in out["rows"]:
        cells = [str(r["views"])]
        cells += [f"{r[m][f]:.3f}" for m in methods for f in FIELDS]
        p = r["paper_table_i_pg_f1"]
        cells.append("—" if p is None else f"{p:.3f}")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--counts", type=int, nargs="+", default=[10, 30, 60])
    parser.add_argument("--scenes", type=int, default=10, help="scenes per count")
    parser.add_argument("--subsets", type=int, default=8, help="random view subsets per k")
    parser.add_argument("--views-range", type=int, nargs=2, default=[2, 10], metavar=("MIN", "MAX"))
    parser.add_argument("--seed", type=int, default=0, help="NumPy seed of the view subsets")
    parser.add_argument("--grid-seed", type=int, default=0, help="Grid.seed (scene keys)")
    parser.add_argument("--out", default=os.path.join("experiments", "figures"))
    args = parser.parse_args(argv)

    out = run(views_range=args.views_range, counts=args.counts, scenes=args.scenes, subsets=args.subsets,
              seed=args.seed, grid_seed=args.grid_seed)
    per_scene = out.pop("_per_scene")
    os.makedirs(args.out, exist_ok=True)
    json_path = os.path.join(args.out, "views_ablation.json")
    with open(json_path, "w") as f:
        json.dump(out, f, indent=2)
    png_path = os.path.join(args.out, "views_ablation.png")
    fig = views_ablation(per_scene["views"], {n: m["pg_f1"] for n, m in per_scene["metrics"].items()}, path=png_path)
    try:
        import matplotlib.pyplot as plt

        plt.close(fig)
    except Exception:  # pragma: no cover
        pass
    print(markdown_table(out))
    print(f"\ntotal {out['total_seconds']:.1f} s; wrote {json_path} and {png_path}")
    return out


if __name__ == "__main__":
    main()
