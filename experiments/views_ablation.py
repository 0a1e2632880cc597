"""Views ablation at σ = 3 px (paper Table I).

Question: how does PG-F1 (and mP-F1, G-F1) of every registered method (``--methods``; C-DOG's
presets and the baselines) change with
the number of views k = 2 … 10, when the k views are drawn at random from the built-in
10-camera rig (``cdog_jax.synthetic.default_rig()``)? The paper's Table I reports PG-F1 at
σ = 3 for 2 … 10 views: 0.766, 0.726, 0.562, 0.601, 0.668, 0.685, 0.719, 0.747, 0.761.

Method: for every k, ``--subsets`` subsets of k distinct views are drawn with a NumPy RNG
(``--seed``); the 10-view "subset" is the whole rig, so repeats are skipped there. Each
subset runs one :func:`cdog_jax.benchmark.sweep` on ``Grid(sigmas=(3.0,), counts, scenes,
views=subset)`` with every jittable method, ``timing=False`` and a single capacity bucket
(the largest count); host methods (``exact``) run the same scenes with
:func:`cdog_jax.benchmark.sweep_host` (scenes they refuse are left out). Subsets run round
robin over k (the first subset of every k, then the second, …); with ``--budget-s`` each
of the two groups starts no new subset after that many seconds, so a slow group covers
every k (its first subset always runs) with fewer subsets (the JSON and the table record the subsets run per method). Per-scene metrics of all subsets of one k are pooled and averaged by the rule of
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
        [--views-range 2 10] [--seed 0] [--out experiments/figures] [--methods all|a,b]
        [--budget-s S]

Writes ``views_ablation.json`` and ``views_ablation.png`` into ``--out`` and prints a
Markdown table.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import time

import numpy as np

from cdog_jax import method_from, method_names
from cdog_jax.benchmark import Grid, sweep, sweep_host
from cdog_jax.metrics import Metrics
from cdog_jax.synthetic import default_rig
from cdog_jax.viz import views_ablation

SIGMA = 3.0
FIELDS = ("pg_f1", "mp_f1", "g_f1")
METRIC_FIELDS = tuple(f.name for f in dataclasses.fields(Metrics))
# PG-F1 of the paper's Table I at σ = 3 px, by number of views (the figure draws the same).
PAPER_TABLE_I = dict(
    zip(range(2, 11), (0.766, 0.726, 0.562, 0.601, 0.668, 0.685, 0.719, 0.747, 0.761))
)


def draw_subsets(
    num_views: int, k: int, subsets: int, rng: np.random.Generator
) -> list[tuple[int, ...]]:
    """``subsets`` distinct sorted k-subsets of ``range(num_views)`` (fewer when not possible)."""
    from math import comb

    want = min(subsets, comb(num_views, k))
    out: list[tuple[int, ...]] = []
    while len(out) < want:
        s = tuple(sorted(int(v) for v in rng.choice(num_views, size=k, replace=False)))
        if s not in out:
            out.append(s)
    return out


def _host_sweep_admissible(rig, grid, name, method):
    """:func:`sweep_host` of one method on ``grid``, leaving out the counts whose scenes it
    refuses (largest first); None when it refuses every count."""
    while True:
        try:
            return sweep_host(rig, grid, {name: method}, buckets=(max(grid.counts),))
        except ValueError as err:
            if f"sweep_host (method {name!r}, scene" not in str(err) or len(grid.counts) == 1:
                if f"sweep_host (method {name!r}, scene" in str(err):
                    return None
                raise
            grid = grid.replace(counts=grid.counts[:-1])


def run(
    *,
    views_range=(2, 10),
    counts=(10, 30, 60),
    scenes=10,
    subsets=8,
    seed=0,
    grid_seed=0,
    methods=None,
    budget_s=None,
    log=print,
):
    """Run the ablation; returns a JSON-able dict of the per-k means and run details."""
    rig = default_rig()
    names = list(method_names()) if methods is None else list(methods)
    configs = {n: method_from(n, "views_ablation --methods") for n in names}
    compiled = {n: m for n, m in configs.items() if m.jittable}
    host = {n: m for n, m in configs.items() if not m.jittable}
    rng = np.random.default_rng(seed)
    counts = tuple(int(c) for c in counts)
    ks = list(range(int(views_range[0]), int(views_range[1]) + 1))
    if ks[0] < 2 or ks[-1] > rig.num_views:
        raise ValueError(f"views range must lie in [2, {rig.num_views}]; got {views_range}")
    subs_of = {k: draw_subsets(rig.num_views, k, subsets, rng) for k in ks}
    # Round robin: the first subset of every k, then the second, … (a budget cut keeps every k).
    schedule = [(k, j) for j in range(subsets) for k in ks if j < len(subs_of[k])]
    pooled = {k: {n: [] for n in configs} for k in ks}
    num_points = {k: [] for k in ks}
    compile_s = {k: 0.0 for k in ks}
    ran = {n: {k: 0 for k in ks} for n in configs}
    t_all = time.perf_counter()
    for group in ([compiled] if compiled else []) + [{n: m} for n, m in host.items()]:
        t0 = time.perf_counter()
        for k, j in schedule:
            if (
                budget_s is not None and j > 0 and time.perf_counter() - t0 > budget_s
            ):  # every k runs once
                log(
                    f"  {', '.join(group)}: budget spent after {sum(ran[next(iter(group))].values())} subsets"
                )
                break
            grid = Grid(
                sigmas=(SIGMA,), counts=counts, scenes=scenes, seed=grid_seed, views=subs_of[k][j]
            )
            if group is compiled:
                res = sweep(
                    rig,
                    grid,
                    methods=compiled,
                    buckets=(max(counts),),
                    timing=False,
                    progress=False,
                )
                compile_s[k] += res.compile_s
                num_points[k].append(res.num_points)
            else:
                ((name, method),) = group.items()
                res = _host_sweep_admissible(rig, grid, name, method)
                if res is None:
                    continue
            for name in group:
                pooled[k][name].append(res.metrics[name])
                ran[name][k] += 1
        log(f"  {', '.join(group)}: {time.perf_counter() - t0:.1f} s")
    rows, per_scene_views, per_scene = (
        [],
        {n: [] for n in configs},
        {name: {f: [] for f in FIELDS} for name in configs},
    )
    for k in ks:
        pts = np.concatenate(num_points[k]) if num_points[k] else np.zeros(0)
        row = {
            "views": k,
            "subsets": [list(s) for s in subs_of[k]],
            "num_scenes": {},
            "mean_points": float(np.mean(pts)) if pts.size else float("nan"),
            "paper_table_i_pg_f1": PAPER_TABLE_I.get(k),
            "compile_s": compile_s[k],
            "subsets_run": {n: ran[n][k] for n in configs},
        }
        for name in configs:
            if not pooled[k][name]:
                row[name] = {f: float("nan") for f in ("pg_f1", "pg_p", "pg_r", "mp_f1", "g_f1")}
                row["num_scenes"][name] = 0
                continue
            fields = {f: np.concatenate([m[f] for m in pooled[k][name]]) for f in METRIC_FIELDS}
            # mean_metrics' rule for scores (a plain mean over all scenes, zeros included);
            # Metrics itself is not built here, its runtime type check wants jax arrays.
            row[name] = {
                f: float(np.mean(fields[f].astype(np.float64)))
                for f in ("pg_f1", "pg_p", "pg_r", "mp_f1", "g_f1")
            }
            row["num_scenes"][name] = int(fields["pg_f1"].size)
            for f in FIELDS:
                per_scene[name][f].append(fields[f])
            per_scene_views[name].append(np.full(fields["pg_f1"].size, k))
        rows.append(row)
        log(f"k={k}: " + ", ".join(f"{n} {row[n]['pg_f1']:.3f}" for n in configs) + " (PG-F1)")
    return {
        "sigma_px": SIGMA,
        "counts": list(counts),
        "scenes_per_cell": scenes,
        "subsets_per_k": subsets,
        "seed": seed,
        "grid_seed": grid_seed,
        "budget_s": budget_s,
        "methods": list(configs),
        "rows": rows,
        "total_seconds": time.perf_counter() - t_all,
        "_per_scene": {
            "views": {
                n: np.concatenate(v) if v else np.zeros(0) for n, v in per_scene_views.items()
            },
            "metrics": {
                n: {f: np.concatenate(v) if v else np.zeros(0) for f, v in d.items()}
                for n, d in per_scene.items()
            },
        },
    }


def markdown_table(out: dict) -> str:
    """One table per score (rows: number of views; columns: methods, then the paper's Table I
    for PG-F1), then the subsets each method ran where a budget cut it short."""
    methods = out["methods"]
    lines = []
    for f, label in (("pg_f1", "PG-F1"), ("g_f1", "G-F1"), ("mp_f1", "mP-F1")):
        head = ["views"] + list(methods) + (["paper Table I"] if f == "pg_f1" else [])
        lines += [f"**{label}**", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for r in out["rows"]:
            cells = [str(r["views"])] + [
                "–" if r[m][f] != r[m][f] else f"{r[m][f]:.3f}" for m in methods
            ]
            if f == "pg_f1":
                p = r["paper_table_i_pg_f1"]
                cells.append("—" if p is None else f"{p:.3f}")
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    short = [
        m for m in methods if any(r["subsets_run"][m] < len(r["subsets"]) for r in out["rows"])
    ]
    if short:
        lines.append(
            "Subsets run per k (of " + ", ".join(str(len(r["subsets"])) for r in out["rows"]) + "):"
        )
        lines.append("")
        lines += [
            f"- {m}: " + ", ".join(str(r["subsets_run"][m]) for r in out["rows"]) for m in short
        ]
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--counts", type=int, nargs="+", default=[10, 30, 60])
    parser.add_argument("--scenes", type=int, default=10, help="scenes per count")
    parser.add_argument("--subsets", type=int, default=8, help="random view subsets per k")
    parser.add_argument("--views-range", type=int, nargs=2, default=[2, 10], metavar=("MIN", "MAX"))
    parser.add_argument("--seed", type=int, default=0, help="NumPy seed of the view subsets")
    parser.add_argument("--grid-seed", type=int, default=0, help="Grid.seed (scene keys)")
    parser.add_argument("--out", default=os.path.join("experiments", "figures"))
    parser.add_argument(
        "--methods", default="all", help="'all' (every registered method) or a comma-separated list"
    )
    parser.add_argument(
        "--budget-s",
        type=float,
        default=None,
        help="seconds per group (the compiled methods together; each host method) before it starts no new subset",
    )
    args = parser.parse_args(argv)

    methods = (
        None if args.methods == "all" else [n.strip() for n in args.methods.split(",") if n.strip()]
    )
    out = run(
        views_range=args.views_range,
        counts=args.counts,
        scenes=args.scenes,
        subsets=args.subsets,
        seed=args.seed,
        grid_seed=args.grid_seed,
        methods=methods,
        budget_s=args.budget_s,
    )
    per_scene = out.pop("_per_scene")
    os.makedirs(args.out, exist_ok=True)
    json_path = os.path.join(args.out, "views_ablation.json")
    with open(json_path, "w") as f:
        json.dump(out, f, indent=2)
    png_path = os.path.join(args.out, "views_ablation.png")
    ran = [n for n, v in per_scene["views"].items() if v.size]
    fig = views_ablation(
        {n: per_scene["views"][n] for n in ran},
        {n: per_scene["metrics"][n]["pg_f1"] for n in ran},
        path=png_path,
    )
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
