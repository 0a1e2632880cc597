"""Real data anyone can reproduce: the Pose2Sim 0.7.2 demo (BSD 3-Clause), associated joint by joint.

The demo ships inside the ``pose2sim`` wheel on PyPI: a Qualisys calibration
(``Calib.qca.txt``, 4 cameras of 1088×1920 px with lens distortion) and OpenPose BODY_25B
detections (one JSON file per frame and camera) of single- and two-participant trials.
This script downloads the wheel once into a cache folder (``pip download --no-deps
pose2sim==0.7.2``; nothing is written into the repository but the figure and, with
``--results``, a section of RESULTS.md), reads the calibration with
``cdog_jax.io.load_rig`` and each trial with ``cdog_jax.io.load_openpose``, and
associates every joint type of every frame in one call (``cdog_jax.associate_classes``;
σ estimated per frame from all joint types pooled). It reports, per trial and preset:

- reprojection errors: each 3D point's mean distance to its members (px, undistorted);
- groups per joint type and frame against the participants of the trial (1 or 2): how
  often a joint type gives exactly as many 3D points as there are participants, fewer
  (a joint missed) or more (a background person, a split, a false detection); and
  against the people visible: the second-largest number of detections of that joint type
  over the views (instances that two views could show, background people included;
  the demo has no 3D ground truth);
- a figure of one frame: the 4 views with each group's detections in one colour (grey:
  unassigned) and the 3D points joined into skeletons.

    python experiments/real_pose2sim.py                       # download (once), run, print
    python experiments/real_pose2sim.py --results experiments/RESULTS.md --figure experiments/figures/pose2sim.png
    python experiments/real_pose2sim.py --demo-dir DIR        # a demo folder already unpacked
    python experiments/real_pose2sim.py --presets paper,extended,best --sigma-pools best
"""

from __future__ import annotations

import argparse
import glob
import os
import subprocess
import sys
import time
import zipfile

import numpy as np

VERSION = "0.7.2"
DEMO_PREFIX = "Pose2Sim/S00_Demo_Session/"
DEFAULT_CACHE = os.path.join(os.path.expanduser("~"), ".cache", "cdog_jax", f"pose2sim-{VERSION}")
# BODY_25B bones (Pose2Sim's skeleton tree, the hip centre left out; eyes and ears as in COCO).
BONES = [
    ("RHip", "RKnee"),
    ("RKnee", "RAnkle"),
    ("RAnkle", "RBigToe"),
    ("RBigToe", "RSmallToe"),
    ("RAnkle", "RHeel"),
    ("LHip", "LKnee"),
    ("LKnee", "LAnkle"),
    ("LAnkle", "LBigToe"),
    ("LBigToe", "LSmallToe"),
    ("LAnkle", "LHeel"),
    ("RHip", "LHip"),
    ("Neck", "RHip"),
    ("Neck", "LHip"),
    ("Neck", "Head"),
    ("Head", "Nose"),
    ("Nose", "LEye"),
    ("Nose", "REye"),
    ("LEye", "LEar"),
    ("REye", "REar"),
    ("Neck", "RShoulder"),
    ("RShoulder", "RElbow"),
    ("RElbow", "RWrist"),
    ("Neck", "LShoulder"),
    ("LShoulder", "LElbow"),
    ("LElbow", "LWrist"),
]


def fetch_demo(cache: str) -> str:
    """The unpacked demo folder under ``cache``; downloads the wheel with pip the first time."""
    demo = os.path.join(cache, "S00_Demo_Session")
    if os.path.isdir(demo):
        return demo
    os.makedirs(cache, exist_ok=True)
    wheels = glob.glob(os.path.join(cache, f"pose2sim-{VERSION}-*.whl"))
    if not wheels:
        cmd = [
            sys.executable,
            "-m",
            "pip",
            "download",
            "--no-deps",
            f"pose2sim=={VERSION}",
            "-d",
            cache,
            "-q",
        ]
        print("Downloading:", " ".join(cmd))
        subprocess.run(cmd, check=True)
        wheels = glob.glob(os.path.join(cache, f"pose2sim-{VERSION}-*.whl"))
    with zipfile.ZipFile(wheels[0]) as z:
        for name in z.namelist():
            keep = name.startswith(DEMO_PREFIX) and (
                name.endswith(".json") or name.endswith(".qca.txt")
            )
            if keep:
                target = os.path.join(cache, name[len("Pose2Sim/") :])
                os.makedirs(os.path.dirname(target), exist_ok=True)
                with z.open(name) as src, open(target, "wb") as dst:
                    dst.write(src.read())
    return demo


def find_inputs(demo: str) -> tuple[str, list[tuple[str, str, int]]]:
    """The calibration file and the trials ``(name, pose folder, participants)``."""
    calib = sorted(glob.glob(os.path.join(demo, "**", "*.qca.txt"), recursive=True))
    if not calib:
        raise SystemExit(f"{demo}: no .qca.txt calibration found")
    trials = []
    for pose in sorted(glob.glob(os.path.join(demo, "**", "pose"), recursive=True)):
        name = os.path.basename(os.path.dirname(pose))
        participants = (
            2 if "Participants1-2" in name else 1
        )  # the demo's trial names say who is filmed
        trials.append((name, pose, participants))
    return calib[0], trials


def associate_trial(rig_file, pose: str, preset: str, sigma="auto", sigma_pool: str = "frame"):
    """Read one trial and associate all its joints (σ estimated and pooled as ``sigma_pool``
    says, or a given σ in px); returns ``(detections, ClassAssociation, seconds)``."""
    import jax

    from cdog_jax import associate_classes
    from cdog_jax.io import load_openpose

    det = load_openpose(
        pose, keypoints="BODY_25B", num_views=rig_file.rig.num_views, image_size=rig_file.image_size
    )
    dist = rig_file.dist if rig_file.dist is not None and np.any(rig_file.dist) else None
    t0 = time.perf_counter()
    out = associate_classes(
        rig_file.rig,
        det.xy.astype(np.float32),
        det.mask,
        det.classes,
        class_names=det.class_names,
        method=preset,
        sigma=sigma,
        sigma_pool=sigma_pool,
        dist=dist,
    )
    jax.block_until_ready(out.association.points3d)
    return det, out, time.perf_counter() - t0


def trial_stats(det, out, participants: int) -> dict:
    """Numbers of one trial (see the module docstring)."""
    a = out.association
    valid = np.asarray(a.valid)
    err = np.asarray(a.err_px)[valid]
    F = valid.shape[0]
    C = out.num_classes
    per = np.zeros((F, C), np.int64)
    f, g = np.nonzero(valid)
    np.add.at(per, (f, out.group_class[f, g]), 1)
    # Instances of a joint type that 2 views could show: the second-largest count of its
    # detections over the views (people in the background count; there is no ground truth).
    counts = np.stack(
        [((det.classes == c) & det.mask).sum(axis=2) for c in range(C)], axis=1
    )  # (F, C, M)
    visible = np.sort(counts, axis=2)[:, :, -2]
    seen = visible >= 1
    n_views = np.asarray(a.n_views)[valid]
    return {
        "frames": F,
        "detections": int(det.mask.sum()),
        "assigned": int((np.asarray(a.labels) >= 0).sum()),
        "points": int(valid.sum()),
        "err_median": float(np.median(err)) if err.size else float("nan"),
        "err_p90": float(np.percentile(err, 90)) if err.size else float("nan"),
        "views_mean": float(n_views.mean()) if n_views.size else float("nan"),
        "sigma_median": float(np.median(np.asarray(a.sigma_px))),
        "sigma_min": float(np.min(np.asarray(a.sigma_px))),
        "sigma_max": float(np.max(np.asarray(a.sigma_px))),
        "pairs": int(seen.sum()),
        "exact": float(np.mean(per[seen] == participants)),
        "fewer": float(np.mean(per[seen] < participants)),
        "more": float(np.mean(per[seen] > participants)),
        "visible_exact": float(np.mean(per[seen] == visible[seen])),
        "visible_fewer": float(np.mean(per[seen] < visible[seen])),
        "visible_more": float(np.mean(per[seen] > visible[seen])),
    }


def sigma_table(rig_file, trials, preset: str, given: float, stats: dict) -> list[str]:
    """The σ table's Markdown lines (printed as they come): the first multi-participant trial
    associated with σ estimated and pooled each way, and with σ given; each row's numbers
    also go into ``stats[name, preset, "sigma", setting]``."""
    name, pose, participants = next(t for t in trials if t[2] > 1)
    lines = [
        f"σ on {name} ({preset}):",
        "",
        "| σ | σ̂ median (range) px | 3D points | assigned | = visible | fewer | more |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    print("\n".join(lines), flush=True)
    settings = (
        ("pooled per frame (default)", "auto", "frame"),
        ("pooled over all frames", "auto", "all"),
        ("per (frame, joint) scene", "auto", "scene"),
        (f"given {given:g} px", given, "frame"),
    )
    for label, sigma, pool in settings:
        det, out, _ = associate_trial(rig_file, pose, preset, sigma=sigma, sigma_pool=pool)
        s = stats[name, preset, "sigma", label] = trial_stats(det, out, participants)
        spread = f" ({s['sigma_min']:.1f}–{s['sigma_max']:.1f})" if pool != "all" else ""
        spread = "" if isinstance(sigma, float) else spread
        lines.append(
            f"| {label} | {s['sigma_median']:.1f}{spread} | {s['points']} | "
            f"{s['assigned'] / s['detections']:.3f} | {s['visible_exact']:.3f} | "
            f"{s['visible_fewer']:.3f} | {s['visible_more']:.3f} |"
        )
        print(lines[-1], flush=True)
    return ["", *lines]


def plot_frame(rig_file, det, out, frame: int, path: str, title: str) -> None:
    """The 4 views of ``frame`` with each group's detections in one colour, and the 3D points
    joined into skeletons (joints linked when their groups share a person in the reference
    view: the 2D person index is an identity within one view)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a = out.association
    labels = np.asarray(a.labels[frame])
    groups = np.asarray(a.groups[frame])
    valid = np.asarray(a.valid[frame])
    X = np.asarray(a.points3d[frame])
    names = out.class_names
    J = len(names)
    M = labels.shape[0]
    w, h = rig_file.image_size
    colours = plt.get_cmap("tab20")
    fig = plt.figure(figsize=(13, 4.6))
    for m in range(M):
        ax = fig.add_subplot(1, M + 2, m + 1)
        ax.set_xlim(0, w)
        ax.set_ylim(h, 0)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        mask = det.mask[frame, m]
        xy = det.xy[frame, m]
        lab = labels[m]
        ax.scatter(*xy[mask & (lab < 0)].T, s=6, c="0.6", marker="x", linewidths=0.6)
        for g in np.unique(lab[mask & (lab >= 0)]):
            ax.scatter(*xy[lab == g].T, s=8, color=colours(int(g) % 20))
        ax.set_title((rig_file.names or [f"view {i}" for i in range(M)])[m], fontsize=8)
    ax3 = fig.add_subplot(1, M + 2, (M + 1, M + 2), projection="3d")
    ref = int(
        np.argmax([(groups[valid][:, m] >= 0).sum() for m in range(M)])
    )  # the view in most groups
    person = np.full(len(groups), -1)
    joint = out.group_class[frame]
    for g in np.flatnonzero(valid):
        if groups[g, ref] >= 0:
            person[g] = groups[g, ref] // J
    people_colours = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple"]
    for p in np.unique(person[person >= 0]):
        at = {names[joint[g]]: X[g] for g in np.flatnonzero(person == p)}
        for u, v in BONES:
            if u in at and v in at:
                ax3.plot(*np.stack([at[u], at[v]]).T, color=people_colours[p % 5], linewidth=1.5)
    ax3.scatter(
        *X[valid].T,
        s=6,
        c=["k" if person[g] < 0 else people_colours[person[g] % 5] for g in np.flatnonzero(valid)],
    )
    ax3.set_title(
        "3D points (m); skeletons by person in " + (rig_file.names or [""] * M)[ref], fontsize=8
    )
    ax3.tick_params(labelsize=6)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    try:
        fig.savefig(path, dpi=70)
    finally:
        plt.close(fig)


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument(
        "--cache", default=DEFAULT_CACHE, help="where the wheel is downloaded and the demo unpacked"
    )
    p.add_argument("--demo-dir", default=None, help="an unpacked demo folder (no download)")
    p.add_argument("--presets", default="paper,extended", help="comma-separated presets")
    p.add_argument(
        "--figure", default=None, help="figure of one frame of the multi-participant trial (.png)"
    )
    p.add_argument("--frame", type=int, default=50, help="frame of the figure")
    p.add_argument(
        "--sigma-pools",
        metavar="PRESET",
        default=None,
        help="also the σ table: the multi-participant trial with PRESET, σ estimated "
        "per frame from all joint types (the default), once for all frames, per (frame, joint) "
        "scene, and given (--sigma-given)",
    )
    p.add_argument("--sigma-given", type=float, default=8.0, help="the σ table's given σ (px)")
    p.add_argument(
        "--results", default=None, help="append a section with the table to this Markdown file"
    )
    args = p.parse_args(argv)

    from cdog_jax.io import load_rig

    demo = args.demo_dir or fetch_demo(args.cache)
    calib, trials = find_inputs(demo)
    rig_file = load_rig(calib)
    print(
        f"Calibration: {calib}: {rig_file.rig.num_views} views, {rig_file.image_size}, names {rig_file.names}"
    )
    rows, stats = [], {}
    header = (
        "| trial | people | preset | frames | detections | 3D points | assigned | views/point | σ̂ (px) | err median (px) | "
        "err p90 (px) | = people | fewer | more | = visible | fewer | more | time (s) |"
    )
    rows += [header, "|" + "---|" * 3 + "---:|" * 15]
    figure_trial = None
    for preset in args.presets.split(","):
        for name, pose, participants in trials:
            det, out, seconds = associate_trial(rig_file, pose, preset)
            s = trial_stats(det, out, participants)
            stats[name, preset] = s
            rows.append(
                f"| {name} | {participants} | {preset} | {s['frames']} | {s['detections']} | {s['points']} | "
                f"{s['assigned'] / s['detections']:.3f} | {s['views_mean']:.2f} | {s['sigma_median']:.1f} | "
                f"{s['err_median']:.1f} | {s['err_p90']:.1f} | {s['exact']:.3f} | {s['fewer']:.3f} | {s['more']:.3f} | "
                f"{s['visible_exact']:.3f} | {s['visible_fewer']:.3f} | {s['visible_more']:.3f} | {seconds:.2f} |"
            )
            print(rows[-1], flush=True)
            if participants > 1 and figure_trial is None and args.figure:
                figure_trial = (name, det, out, preset)
    if args.figure and figure_trial is not None:
        name, det, out, preset = figure_trial
        frame = min(args.frame, det.mask.shape[0] - 1)
        plot_frame(
            rig_file,
            det,
            out,
            frame,
            args.figure,
            f"Pose2Sim demo {name}, frame {frame}, {preset} preset",
        )
        print(f"Figure: {args.figure} ({os.path.getsize(args.figure) // 1024} KB)")
    if args.sigma_pools:
        rows += sigma_table(rig_file, trials, args.sigma_pools, args.sigma_given, stats)
    if args.results:
        with open(args.results, "a") as f:
            f.write("\n" + "\n".join(rows) + "\n")
        print(f"Appended the table to {args.results}")
    return stats


if __name__ == "__main__":
    main()
