"""Does every stage of the default method earn its place? ``best()`` with one stage or option
left out at a time, on real detections and on synthetic scenes side by side.

- Real: Shelf's dev frames (the even blocks of 25), as a user runs them: ``cdog-jax
  associate`` on the OpenPose folders that :mod:`shelf` writes (its defaults otherwise: the
  person vote and the temporal prior), scored by :mod:`shelf_score` (PCP, recall@10cm,
  MPJPE). The held-out frames are never scored here.
- Synthetic: a sub-grid of docs/BENCHMARK.md §1 (10 views; ``--sigmas``, every count of
  the paper's grid, ``--scenes`` per cell), PG-F1 and G-F1 per σ.

Each variant is registered as a method (``cdog_jax.register_method``) and the command runs
in this process, so each compiles once. A stage pays when leaving it out loses on either
yardstick; one that loses on neither is a candidate to go.

    python experiments/real/shelf_ablation.py PATH/TO/data/shelf [--work DIR] [--out rows.json]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import runpy
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
shelf = runpy.run_path(os.path.join(HERE, "shelf.py"), run_name="shelf")
shelf_score = runpy.run_path(os.path.join(HERE, "shelf_score.py"), run_name="shelf_score")

#: ``best()`` and, for each of its stages and options, ``best()`` without it.
LEFT_OUT: dict[str, dict] = {
    "best()": {},
    "− detach_ambiguous": {"detach_ambiguous": False},
    "− support_filter": {"support_filter": False},
    "− reassign": {"reassign": False},
    "− seed": {"seed": False},
    "− regroup": {"regroup": False},
    "− recover": {"recover": False},
    "mutual adjacency": {"adjacency": "mutual"},
    "− IQR": {"iqr": False},
    "− BPE filter": {"bpe_filter": False},
    "− δ-pruning": {"prune_scope": "none"},
    # the three that change neither yardstick above, left out together
    "− IQR − BPE filter − regroup": {"iqr": False, "bpe_filter": False, "regroup": False},
}


def variants(rows: list[str]) -> dict[str, str]:
    """Register the variants named ``rows`` as methods; returns each one's registered name."""
    from cdog_jax import Config, register_method

    names = {}
    for row in rows:
        options = LEFT_OUT[row]
        name = f"ablation{list(LEFT_OUT).index(row)}"
        register_method(name, lambda options=options: Config.best(**options))
        names[row] = name
    return names


def real_rows(data: str, work: str, names: dict[str, str]) -> list[dict]:
    """Every variant through ``cdog-jax associate`` on Shelf, scored on the dev frames."""
    from cdog_jax.cli import main

    ready = shelf["prepare"](data, work)
    frames = shelf["split_frames"](ready["frames"], "dev")
    rows = []
    for row, method in names.items():
        out = os.path.join(work, f"{method}.npz")
        argv = ["associate", "--rig", ready["rig"], "--points", ready["pose"]]
        argv += ["--keypoints", "BODY_25", "--method", method, "--out", out]
        start = time.perf_counter()
        with contextlib.redirect_stdout(io.StringIO()):
            if main(argv) != 0:
                raise SystemExit(f"{row}: cdog-jax associate failed")
        seconds = time.perf_counter() - start
        with np.load(out) as result:
            report = shelf_score["score"](dict(result), ready["gt"], frames)
        rows.append({"variant": row, "seconds": round(seconds, 1), **report})
        print(
            f"  {row}: PCP {report['pcp_mean']:.1f}, recall {report['recall_10cm']:.3f}, "
            f"MPJPE {report['mpjpe_mm']:.1f} mm ({seconds:.0f} s, compile included)",
            flush=True,
        )
    return rows


def synthetic_rows(names: dict[str, str], sigmas, counts, scenes: int) -> list[dict]:
    """Every variant on the synthetic sub-grid: mean PG-F1 and G-F1 per σ."""
    from cdog_jax import method_from
    from cdog_jax.benchmark import Grid, sweep
    from cdog_jax.synthetic import default_rig

    counts = tuple(counts or Grid.paper().counts)
    grid = Grid(sigmas=tuple(sigmas), counts=counts, scenes=scenes, seed=100)
    methods = {row: method_from(name, "shelf_ablation") for row, name in names.items()}
    res = sweep(default_rig(), grid, methods=methods, timing=False)
    rows = []
    for row in methods:
        m = res.metrics[row]
        per_sigma = {}
        for sigma in grid.sigmas:
            where = np.isclose(res.sigma, sigma)
            per_sigma[f"{sigma:g}"] = {
                "pg_f1": round(float(np.mean(m["pg_f1"][where])), 4),
                "g_f1": round(float(np.mean(m["g_f1"][where])), 4),
            }
        rows.append({"variant": row, "synthetic": per_sigma})
    return rows


def markdown(real: list[dict], synthetic: list[dict], sigmas) -> str:
    by_variant = {r["variant"]: r for r in synthetic}
    head = " | ".join(f"PG-F1 / G-F1, σ = {s:g}" for s in sigmas)
    lines = [
        f"| variant | Shelf dev: PCP | recall@10cm | MPJPE (mm) | {head} |",
        "|---" * (4 + len(sigmas)) + "|",
    ]
    for r in real:
        syn = by_variant.get(r["variant"], {}).get("synthetic", {})
        cells = " | ".join(
            f"{syn[f'{s:g}']['pg_f1']:.3f} / {syn[f'{s:g}']['g_f1']:.3f}" if syn else ""
            for s in sigmas
        )
        lines.append(
            f"| {r['variant']} | {r['pcp_mean']:.1f} | {r['recall_10cm']:.3f} | "
            f"{r['mpjpe_mm']:.1f} | {cells} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("data", help="a local copy of the 4D-association repository's data/shelf")
    parser.add_argument(
        "--work", default=os.path.join(os.path.expanduser("~"), ".cache", "cdog_jax", "ablation")
    )
    parser.add_argument(
        "--variants", default=None, help="comma-separated rows of LEFT_OUT (default: all)"
    )
    parser.add_argument("--sigmas", type=float, nargs="+", default=[1.0, 3.0])
    parser.add_argument("--counts", type=int, nargs="+", help="(default: the paper's grid)")
    parser.add_argument("--scenes", type=int, default=1, help="synthetic scenes per grid cell")
    parser.add_argument("--skip-synthetic", action="store_true")
    parser.add_argument("--out", default=None, help="also write the rows as JSON here")
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    chosen = list(LEFT_OUT) if args.variants is None else args.variants.split(",")
    unknown = [v for v in chosen if v not in LEFT_OUT]
    if unknown:
        parser.error(f"unknown variant {unknown[0]!r}; known: {', '.join(LEFT_OUT)}")
    names = variants(chosen)
    print("Shelf dev frames, cdog-jax associate with each variant:", flush=True)
    real = real_rows(args.data, args.work, names)
    synthetic = (
        [] if args.skip_synthetic else synthetic_rows(names, args.sigmas, args.counts, args.scenes)
    )
    print(markdown(real, synthetic, args.sigmas if synthetic else []))
    rows = {"real": real, "synthetic": synthetic}
    if args.out:
        with open(args.out, "w") as f:
            json.dump(rows, f, indent=1)
    return rows


if __name__ == "__main__":
    main()
