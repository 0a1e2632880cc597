"""Shelf's numbers for the defaults and each preset: the table of RESULTS.md "Shelf: real
OpenPose detections".

For every setting (command-line options of ``cdog-jax associate``) the whole command runs on
all of Shelf's frames as a user runs it (:mod:`shelf`), twice: the first run compiles (the
compiled programs persist on disk), the second is the warm wall time a user sees from then
on. Each result is scored on one split (dev by default: develop and tune on these only;
``--split held-out`` once, at the end). Beside them, the 4D-association system's own output
(``skel.txt`` of the same folder) through the same evaluator.

    python experiments/real/shelf_table.py PATH/TO/data/shelf [--split dev] [--markdown out.md]
"""

from __future__ import annotations

import argparse
import json
import os
import runpy
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
shelf = runpy.run_path(os.path.join(HERE, "shelf.py"), run_name="shelf")
shelf_score = runpy.run_path(os.path.join(HERE, "shelf_score.py"), run_name="shelf_score")

SETTINGS: dict[str, list[str]] = {
    "defaults": [],  # best(), the person vote and the temporal prior
    "--no-temporal-prior": ["--no-temporal-prior"],
    "--no-person-vote --no-temporal-prior": ["--no-person-vote", "--no-temporal-prior"],
    "--method extended": ["--method", "extended"],
    "--method paper": ["--method", "paper"],
    "--method reference": ["--method", "reference"],
    # σ fitted once on every frame's detections pooled, then held (what a live loop that
    # does not fit σ per frame gets; docs/LIVE.md): computed by held_sigma_options.
    "--sigma held": None,
}


def held_sigma_options(ready: dict) -> list[str]:
    """``--sigma σ`` with the one σ (px) that ``class_sigmas(..., pool="all")`` fits on all
    the recording's detections, as the command reads them."""
    import cdog_jax
    from cdog_jax.io import load_openpose, load_rig

    rig = load_rig(ready["rig"])
    det = load_openpose(ready["pose"], keypoints="BODY_25")
    classes = np.where(det.mask, det.classes, 0)
    sigma = cdog_jax.class_sigmas(rig.rig, det.xy, det.mask, classes, pool="all", dist=rig.dist)
    return ["--sigma", f"{float(sigma[0]):.4f}"]


def run_setting(
    ready: dict, name: str, options: list[str], frames, work: str, runs: int = 2
) -> dict:
    """Run ``cdog-jax associate`` with ``options`` ``runs`` times; score the last result."""
    out = os.path.join(work, f"result_{len(os.listdir(work))}.npz")
    seconds = [shelf["run_command"](ready["rig"], ready["pose"], out, options) for _ in range(runs)]
    with np.load(out) as result:
        row = shelf_score["score"](dict(result), ready["gt"], frames)
    row.update(setting=name, first_s=round(seconds[0], 1), warm_s=round(seconds[-1], 1))
    return row


def four_d_row(data: str, count: int, frames) -> dict | None:
    """The 4D-association output ``skel.txt`` (SKEL19 joints) through the same evaluator."""
    path = os.path.join(data, "skel.txt")
    if not os.path.exists(path):
        return None
    skeletons = shelf["read_skeletons"](path)[:count]
    body = [
        {k: shelf_score["body25_from_skel19"](v) for k, v in frame.items()} for frame in skeletons
    ]
    row = shelf_score["score_skeletons"](
        body, shelf["read_skeletons"](os.path.join(data, "gt.txt"))[:count], frames
    )
    row.update(setting="4D association (its skel.txt)", first_s=None, warm_s=None)
    return row


def markdown(rows: list[dict], split: str, frames: int) -> str:
    lines = [
        f"| setting ({split} frames of {frames}) | PCP actor 1 / 2 / 3 | PCP mean | recall@10cm | MPJPE (mm) | command, first / warm (s) |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        actors = " / ".join(f"{r['pcp'].get(f'actor {a}', float('nan')):.1f}" for a in (1, 2, 3))
        wall = "" if r["first_s"] is None else f"{r['first_s']:.1f} / {r['warm_s']:.1f}"
        lines.append(
            f"| {r['setting']} | {actors} | {r['pcp_mean']:.1f} | {r['recall_10cm']:.3f} | {r['mpjpe_mm']:.1f} | {wall} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "data", help="a local copy of the 4D-association repository's data/shelf folder"
    )
    parser.add_argument(
        "--work", default=os.path.join(os.path.expanduser("~"), ".cache", "cdog_jax", "shelf")
    )
    parser.add_argument("--frames", type=int, default=None, help="only the first N frames")
    parser.add_argument("--split", choices=("dev", "held-out", "all"), default="dev")
    parser.add_argument(
        "--settings", default=None, help="comma-separated names of SETTINGS (default: all)"
    )
    parser.add_argument(
        "--runs", type=int, default=2, help="runs of each command (the last is timed as warm)"
    )
    parser.add_argument("--markdown", default=None, help="also write the table to this file")
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    names = (
        list(SETTINGS) if args.settings is None else [n.strip() for n in args.settings.split(",")]
    )
    unknown = [n for n in names if n not in SETTINGS]
    if unknown:
        parser.error(f"unknown setting {unknown[0]!r}; known: {', '.join(SETTINGS)}")
    ready = shelf["prepare"](args.data, args.work, args.frames)
    frames = shelf["split_frames"](ready["frames"], args.split)
    runs = os.path.join(args.work, "runs")
    os.makedirs(runs, exist_ok=True)
    rows = []
    for n in names:
        options = SETTINGS[n] if SETTINGS[n] is not None else held_sigma_options(ready)
        rows.append(run_setting(ready, n, options, frames, runs, args.runs))
        if SETTINGS[n] is None:
            rows[-1]["setting"] = " ".join(options) + " (the recording's σ, fitted once)"
    four_d = four_d_row(args.data, ready["frames"], frames)
    if four_d is not None:
        rows.append(four_d)
    table = markdown(rows, args.split, ready["frames"])
    print(table)
    print(json.dumps(rows, indent=1))
    if args.markdown:
        with open(args.markdown, "w") as f:
            f.write(table + "\n")
    return rows


if __name__ == "__main__":
    main()
