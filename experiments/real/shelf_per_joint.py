"""Shelf joint by joint: every (frame, joint type) of the OpenPose detections a scene of its
own, as a user without classes or people would run them, and which rule costs real recall.

Each scene holds one joint type's detections in the five views (one per person OpenPose
found, plus its spurious ones); nothing links joints or frames: no person vote, no temporal
prior, σ estimated per scene (``associate_classes(..., sigma_pool="scene")``, which is one
``associate`` per scene, batched). Scored on Shelf's dev frames (the even blocks of 25) by
recall@10cm of the 12 limb joints (:mod:`shelf_score`); ``--split held-out`` scores the odd
blocks instead, once, when nothing more is to be chosen on them.

The rows: the presets; then ``best()`` with one rule changed at a time: the validity
gate's parallax and error bounds off, σ given instead of estimated, the robust σ
estimator, the gate fitted to the robust estimator's true-pair distances
(``tau_mode="fitted"``; also for ``extended()``), σ pooled over each frame's joint types
(as ``cdog-jax associate`` pools it), and the stages the former default ran. A rule that
costs real recall shows as a row above ``best()``; the ground truth's own grouping bounds
what any rule can reach.

    python experiments/real/shelf_per_joint.py PATH/TO/data/shelf [--rows best,paper] [--out rows.json]
"""

from __future__ import annotations

import argparse
import json
import os
import runpy
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
shelf = runpy.run_path(os.path.join(HERE, "shelf.py"), run_name="shelf")
shelf_score = runpy.run_path(os.path.join(HERE, "shelf_score.py"), run_name="shelf_score")

#: name → (preset, fields of the preset replaced, keywords of associate_classes)
ROWS: dict[str, tuple[str, dict, dict]] = {
    "best()": ("best", {}, {}),
    "extended()": ("extended", {}, {}),
    "paper()": ("paper", {}, {}),
    "reference()": ("reference", {}, {}),
    "best() without the parallax bound": ("best", {"min_parallax_deg": 0.0}, {}),
    "best() without the error bound": ("best", {"max_err_frac": 1000.0}, {}),
    "best() σ = 2 px": ("best", {}, {"sigma": 2.0}),
    "best() σ = 4 px": ("best", {}, {"sigma": 4.0}),
    "best() σ = 8 px": ("best", {}, {"sigma": 8.0}),
    "best() robust σ": ("best", {"sigma_mode": "robust"}, {}),
    "best() fitted gate": ("best", {"sigma_mode": "robust", "tau_mode": "fitted"}, {}),
    "extended() robust σ": ("extended", {"sigma_mode": "robust"}, {}),
    "extended() fitted gate": ("extended", {"sigma_mode": "robust", "tau_mode": "fitted"}, {}),
    "best() σ pooled per frame": ("best", {}, {"sigma_pool": "frame"}),
    "best() with IQR BPE filter regroup": (
        "best",
        {"iqr": True, "bpe_filter": True, "regroup": True},
        {},
    ),
}


def run(rig, det, frames: np.ndarray, method, options: dict) -> tuple[dict, float]:
    """One row: the 3D points per scored frame and joint type, and the wall time (s)."""
    import cdog_jax

    options = {"sigma_pool": "scene", **options}
    start = time.perf_counter()
    out = cdog_jax.associate_classes(
        rig,
        det.xy[frames],
        det.mask[frames],
        det.classes[frames],
        num_classes=len(det.class_names),
        method=method,
        **options,
    )
    a = out.association
    result = {
        "points3d": np.asarray(a.points3d),
        "valid": np.asarray(a.valid),
        "group_class": np.asarray(out.group_class),
    }
    return result, time.perf_counter() - start


def recall_rows(data: str, work: str, methods: dict, split: str = "dev") -> dict:
    """``{name: (recall@10cm, wall s)}`` of each ``methods`` entry (``name: (method,
    associate_classes options)``), every (frame, joint type) of ``split`` a scene of its own."""
    from cdog_jax.io import load_openpose, load_rig

    prepared = shelf["prepare"](data, work)
    rig = load_rig(prepared["rig"]).rig
    det = load_openpose(prepared["pose"], keypoints="BODY_25")
    frames = shelf["split_frames"](prepared["frames"], split)
    truth = [prepared["gt"][f] for f in frames]
    out = {}
    for name, (method, options) in methods.items():
        result, seconds = run(rig, det, frames, method, options)
        points = shelf_score["points_by_joint"](result)
        out[name] = (shelf_score["joint_recall"](points, truth, range(len(frames))), seconds)
    return out


def main(argv: list[str] | None = None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("data", help="a local copy of the 4D-association repository's data/shelf")
    parser.add_argument(
        "--work",
        default=os.path.join(os.path.expanduser("~"), ".cache", "cdog_jax", "shelf"),
        help="where the rig and the OpenPose folders go",
    )
    parser.add_argument("--rows", help=f"comma-separated rows (default all: {', '.join(ROWS)})")
    parser.add_argument("--out", help="also write the rows as JSON here")
    parser.add_argument(
        "--split",
        choices=("dev", "held-out"),
        default="dev",
        help="the frames scored (default dev: the even blocks of 25)",
    )
    args = parser.parse_args(argv)
    names = list(ROWS) if args.rows is None else [r.strip() for r in args.rows.split(",")]
    unknown = [n for n in names if n not in ROWS]
    if unknown:
        parser.error(f"unknown rows {unknown}; choose from {list(ROWS)}")

    import cdog_jax

    methods = {
        name: (getattr(cdog_jax.Config, ROWS[name][0])(**ROWS[name][1]), ROWS[name][2])
        for name in names
    }
    rows = []
    for name, (recall, seconds) in recall_rows(args.data, args.work, methods, args.split).items():
        rows.append({"row": name, "recall_10cm": round(recall, 4), "seconds": round(seconds, 1)})
        print(f"| {name} | {recall:.3f} | {seconds:.1f} s |", flush=True)
    if args.out:
        with open(args.out, "w") as f:
            json.dump(rows, f, indent=1)
    return rows


if __name__ == "__main__":
    main()
