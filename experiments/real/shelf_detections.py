"""What Shelf's real detections look like beside its ground truth: the numbers a synthetic
generator of people has to reproduce.

Each actor's annotated 3D joints (``gt.txt``; the 12 limb joints) are projected into every
camera that sees them in front and inside the image, and met with the OpenPose BODY_25
detections of that joint type in that view, as the command line reads them (the candidates
parsed into people as OpenPose does, :func:`shelf.parse_people`). Within ``--radius`` px of
the projection:

- **found**: a detection of the joint's type; its offset ``(dx, dy)`` is an error sample;
- **swapped**: none of its type, but one of the mirrored type (left for right), which the
  actor's mirrored joint does not explain (that joint projects farther than the radius);
- **missed**: neither.

A missed joint is **hidden by a person** when it falls inside the image box of another
actor's joints (padded by 10 %) whose joints are nearer that camera on average. Also
counted: **doubles** (two detections of the type within the radius) and, per view and
frame, **unexplained** detections of a limb joint type, near no annotated actor's joint of
that type or its mirror (an upper bound on clutter: Shelf annotates actors 1–3 and not
always a fourth person who walks in).

The errors are summarised as a Gaussian bulk and a far share (the options
``Realism.far_share`` / ``far_scale`` and ``view_spread`` of :mod:`cdog_jax.synthetic`):
``σ`` = 1.4826 · MAD of the pooled coordinates, the share of samples with a coordinate
beyond 4 σ, their RMS coordinate over σ, and the spread of ``log σ`` over views. The radius
bounds the errors that count as found, so the tail beyond it is counted as missed.

    python experiments/real/shelf_detections.py PATH/TO/data/shelf            # dev frames
    python experiments/real/shelf_detections.py PATH/TO/data/shelf --radius 40 --json d.json
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import shelf  # noqa: E402
from shelf_score import BODY25_OF_SHELF, LIMB_JOINTS  # noqa: E402

# Shelf's limb joints and their mirror (0 right ankle ↔ 5 left ankle, …, 8 ↔ 9 shoulders).
MIRROR = {0: 5, 1: 4, 2: 3, 3: 2, 4: 1, 5: 0, 6: 11, 7: 10, 8: 9, 9: 8, 10: 7, 11: 6}
JOINT_NAMES = (
    "right ankle",
    "right knee",
    "right hip",
    "left hip",
    "left knee",
    "left ankle",
    "right wrist",
    "right elbow",
    "right shoulder",
    "left shoulder",
    "left elbow",
    "left wrist",
)
FAR_SIGMAS = 4.0  # a coordinate farther than this many σ is in the far share
BOX_PAD = 0.1  # a person's image box padded by this share of its size on each side


def project(K, R, t, X):
    """Pixels ``(..., 2)`` and depth ``(...)`` of world points ``X (..., 3)`` in one camera."""
    cam = X @ R.T + t
    uv = cam @ K.T
    with np.errstate(invalid="ignore", divide="ignore"):
        return uv[..., :2] / uv[..., 2:], cam[..., 2]


SEEN_SHARE = 0.8  # a camera sees a person when this share of its limb joints is in its image


def cameras_seeing(K, R, t, size, joints: np.ndarray) -> np.ndarray:
    """How many of the cameras ``K, R, t`` (``(M, 3, 3)``, ``(M, 3, 3)``, ``(M, 3)``, world to
    camera) see each person of ``joints (..., J, 3)`` (its limb joints, metres): at least
    :data:`SEEN_SHARE` of them in front of the camera and inside its image of ``size``
    (width, height) px. Returns ``(...)`` ints. A camera that looks down its ``-z`` axis
    (``K[2, 2] = -1``) counts depth along ``-z``."""
    W, H = size
    seen = np.zeros(joints.shape[:-2], int)
    for m in range(len(K)):
        p, depth = project(np.asarray(K[m]), np.asarray(R[m]), np.asarray(t[m]), joints)
        front = depth * np.sign(K[m][2, 2]) > 0
        inside = front & (p[..., 0] >= 0) & (p[..., 0] < W) & (p[..., 1] >= 0) & (p[..., 1] < H)
        seen += np.mean(inside, axis=-1) >= SEEN_SHARE
    return seen


def _nearest(points: np.ndarray, at: np.ndarray) -> tuple[float, int]:
    """Distance from ``at (2,)`` to the nearest of ``points (n, 2)`` and its index."""
    if len(points) == 0:
        return np.inf, -1
    d = np.linalg.norm(points - at, axis=1)
    k = int(np.argmin(d))
    return float(d[k]), k


def detection_stats(views, gt, K, R, t, size, frames, radius: float) -> dict:
    """The counts and error samples of the module docstring.

    ``views[m][f]``: view ``m``'s people in frame ``f``, each ``(25, 3)`` (x, y px, score; a
    score of 0: no detection); ``gt[f]``: ``{actor: (15, 3)}`` metres; ``K, R, t``: the
    cameras (world to camera); ``size``: ``(width, height)`` px; ``frames``: the frames to
    measure; ``radius``: px."""
    M = len(views)
    W, H = size
    rows = []  # (frame, actor, joint, view, outcome, hidden, dx, dy)
    doubles = 0
    unexplained = []
    for f in frames:
        actors = {a: j for a, j in gt[f].items() if np.all(np.isfinite(j[list(LIMB_JOINTS)]))}
        for m in range(M):
            dets = {
                j: np.array(
                    [p[BODY25_OF_SHELF[j], :2] for p in views[m][f] if p[BODY25_OF_SHELF[j], 2] > 0]
                ).reshape(-1, 2)
                for j in LIMB_JOINTS
            }
            uv, depth = {}, {}
            for a, joints in actors.items():
                uv[a], depth[a] = project(K[m], R[m], t[m], joints[list(LIMB_JOINTS)])
            boxes = {}
            for a in actors:
                lo, hi = uv[a].min(0), uv[a].max(0)
                pad = BOX_PAD * (hi - lo)
                boxes[a] = (lo - pad, hi + pad, float(np.mean(depth[a])))
            for a in actors:
                for j in LIMB_JOINTS:
                    at = uv[a][j]
                    if not (depth[a][j] > 0 and 0 <= at[0] < W and 0 <= at[1] < H):
                        continue
                    near = np.linalg.norm(dets[j] - at, axis=1) <= radius
                    doubles += int(np.sum(near) >= 2)
                    d_same, k = _nearest(dets[j], at)
                    mirror = MIRROR[j]
                    d_mirror, km = _nearest(dets[mirror], at)
                    hidden = any(
                        b != a
                        and boxes[b][2] < boxes[a][2]
                        and np.all(boxes[b][0] <= at)
                        and np.all(at <= boxes[b][1])
                        for b in actors
                    )
                    if d_same <= radius:
                        dx, dy = dets[j][k] - at
                        rows.append((f, a, j, m, 0, hidden, dx, dy))
                    elif (
                        d_mirror <= radius
                        and np.linalg.norm(dets[mirror][km] - uv[a][mirror]) > radius
                    ):
                        rows.append((f, a, j, m, 1, hidden, np.nan, np.nan))
                    else:
                        rows.append((f, a, j, m, 2, hidden, np.nan, np.nan))
            for j in LIMB_JOINTS:
                ends = [uv[a][k] for a in actors for k in (j, MIRROR[j])]
                for p in dets[j]:
                    if not ends or min(np.linalg.norm(p - e) for e in ends) > radius:
                        unexplained.append((f, m, j))
    table = np.array(rows, float).reshape(-1, 8)
    return _summary(table, doubles, unexplained, len(frames), M, radius)


def _robust_sigma(values: np.ndarray) -> float:
    if values.size == 0:
        return float("nan")
    return float(1.4826 * np.median(np.abs(values - np.median(values))))


def _summary(table, doubles, unexplained, num_frames, M, radius) -> dict:
    outcome, hidden = table[:, 4].astype(int), table[:, 5].astype(bool)
    total = len(table)
    found = outcome == 0
    err = table[found][:, 6:8]
    coords = err.reshape(-1)
    sigma = _robust_sigma(coords)
    far = np.any(np.abs(err - np.median(err, axis=0)) > FAR_SIGMAS * sigma, axis=1)
    far_coords = (err[far] - np.median(err, axis=0)).reshape(-1)
    view_sigmas = [
        _robust_sigma(table[found & (table[:, 3] == m)][:, 6:8].reshape(-1)) for m in range(M)
    ]
    radial = np.linalg.norm(err, axis=1)

    def share(mask, of):
        return float(np.sum(mask & of) / max(np.sum(of), 1))

    per_joint = {
        JOINT_NAMES[j]: {
            "missed": share(outcome == 2, table[:, 2] == j),
            "missed_in_sight": share(outcome == 2, (table[:, 2] == j) & ~hidden),
            "swapped": share(outcome == 1, table[:, 2] == j),
            "median_error_px": float(np.median(radial[table[found][:, 2] == j]))
            if np.any(table[found][:, 2] == j)
            else float("nan"),
        }
        for j in LIMB_JOINTS
    }
    return {
        "radius_px": radius,
        "frames": num_frames,
        "joint_views": total,
        "found": share(found, np.ones(total, bool)),
        "swapped": share(outcome == 1, np.ones(total, bool)),
        "missed": share(outcome == 2, np.ones(total, bool)),
        "hidden_share": share(hidden, np.ones(total, bool)),
        "missed_when_hidden": share(outcome == 2, hidden),
        "missed_when_in_sight": share(outcome == 2, ~hidden),
        "doubles": doubles / max(total, 1),
        "unexplained_per_view_frame": len(unexplained) / max(num_frames * M, 1),
        "sigma_px": sigma,
        "error_p50_px": float(np.percentile(radial, 50)) if radial.size else float("nan"),
        "error_p90_px": float(np.percentile(radial, 90)) if radial.size else float("nan"),
        "error_p99_px": float(np.percentile(radial, 99)) if radial.size else float("nan"),
        "far_share": float(np.mean(far)) if far.size else float("nan"),
        "far_scale": float(np.sqrt(np.mean(far_coords**2)) / sigma)
        if far_coords.size and sigma > 0
        else float("nan"),
        "view_sigmas_px": view_sigmas,
        "view_spread": float(np.std(np.log(view_sigmas)))
        if all(s > 0 for s in view_sigmas)
        else float("nan"),
        "per_joint": per_joint,
    }


def read_views(data: str):
    """The cameras, the image size, each view's people per frame and the ground truth."""
    names, K, R, t, size = shelf.read_calibration(os.path.join(data, "calibration.json"))
    views = []
    for n in names:
        frames = shelf.read_candidates(os.path.join(data, "detection", f"{n}.txt"), size)
        views.append(
            [
                [np.reshape(shelf.person_keypoints(fr, p), (25, 3)) for p in shelf.parse_people(fr)]
                for fr in frames
            ]
        )
    gt = shelf.read_skeletons(os.path.join(data, "gt.txt"))
    return K, R, t, size, views, gt


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("data", help="a local copy of the 4D-association repository's data/shelf folder")
    p.add_argument("--split", choices=("dev", "held-out", "all"), default="dev")
    p.add_argument("--radius", type=float, default=30.0, help="px (default 30)")
    p.add_argument("--json", help="write the numbers here")
    args = p.parse_args(argv)
    K, R, t, size, views, gt = read_views(args.data)
    count = min(len(gt), *(len(v) for v in views))
    frames = shelf.split_frames(count, args.split)
    out = detection_stats(views, gt, K, R, t, size, frames, args.radius)
    actors = [
        j[list(LIMB_JOINTS)]
        for f in frames
        for j in gt[f].values()
        if np.all(np.isfinite(j[list(LIMB_JOINTS)]))
    ]
    seen = cameras_seeing(K, R, t, size, np.array(actors).reshape(-1, len(LIMB_JOINTS), 3))
    out["actor_frames"] = len(actors)
    out["actor_frames_seen_by_every_camera"] = int(np.sum(seen == len(K)))
    print(
        f"{len(frames)} {args.split} frames, {out['joint_views']} (actor, frame, limb joint, "
        f"view) in sight; within {args.radius:g} px:"
    )
    print(
        f"  found {out['found']:.3f}, swapped left/right {out['swapped']:.3f}, missed "
        f"{out['missed']:.3f} (hidden by a person: {out['hidden_share']:.3f} of the joints, "
        f"missed {out['missed_when_hidden']:.3f} of those, {out['missed_when_in_sight']:.3f} "
        f"of the others); doubles {out['doubles']:.4f}; unexplained detections "
        f"{out['unexplained_per_view_frame']:.2f} per view and frame"
    )
    print(
        f"  annotated actors seen by every camera ({SEEN_SHARE:.0%} of their limb joints in "
        f"its image): {out['actor_frames_seen_by_every_camera']} of {out['actor_frames']} "
        "(actor, frame)"
    )
    print(
        f"  errors: σ {out['sigma_px']:.2f} px (1.4826·MAD), radial p50 / p90 / p99 "
        f"{out['error_p50_px']:.1f} / {out['error_p90_px']:.1f} / {out['error_p99_px']:.1f} px; "
        f"far share {out['far_share']:.3f} at {out['far_scale']:.1f} σ; per-view σ "
        + ", ".join(f"{s:.2f}" for s in out["view_sigmas_px"])
        + f" px (log spread {out['view_spread']:.2f})"
    )
    for name, row in out["per_joint"].items():
        print(
            f"  {name:15s} missed {row['missed']:.3f} (in sight {row['missed_in_sight']:.3f})  "
            f"swapped {row['swapped']:.3f}  "
            f"median error {row['median_error_px']:.1f} px"
        )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)
    return out


if __name__ == "__main__":
    main()
