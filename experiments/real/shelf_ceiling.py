"""What Shelf's detections allow: people grouped by the ground truth, triangulated, scored.

The association cannot place a joint that no two views detected, nor find a person that
OpenPose split or merged in every view. This script takes the grouping from the ground
truth instead of from any method, triangulates it the way the library does (DLT,
:func:`cdog_jax.triangulate`) and scores it with the evaluator of the Shelf table
(:mod:`shelf_score`): the rows bound what an association of these detections can reach.

- **people** (``by person``): in every view, each of OpenPose's people (as the command line
  reads them, :func:`shelf.parse_people`) is given to the annotated actor whose projected
  joints it lies nearest (the median pixel distance over the joints both have; one person
  per actor and view, nearest pairs first, at most ``--radius`` px). Each of the actor's 25
  BODY_25 joints is triangulated from the views whose person holds it. This is the best a
  method can do that keeps OpenPose's people whole (as the person vote does).
- **joints** (``by joint``): the same, but each of the 13 annotated joint types is taken
  from the detections of that type in each view, whatever person holds them: each true
  joint's projection takes the nearest one within ``--radius`` px, nearest pairs first, one
  detection per joint (the others, needed for the head, as in ``by person``). This is
  about the best any association of these detections can do that puts each detection in
  one group.

An actor's frame with none of its joints triangulated scores no part, as for a method.

    python experiments/real/shelf_ceiling.py PATH/TO/data/shelf [--split dev] [--radius 40]
"""

from __future__ import annotations

import argparse
import json
import os
import runpy
import sys

import jax.numpy as jnp
import numpy as np

import cdog_jax

HERE = os.path.dirname(os.path.abspath(__file__))
shelf_detections = runpy.run_path(
    os.path.join(HERE, "shelf_detections.py"), run_name="shelf_detections"
)
shelf = shelf_detections["shelf"]
shelf_score = runpy.run_path(os.path.join(HERE, "shelf_score.py"), run_name="shelf_score")

ANNOTATED = shelf_score["BODY25_OF_SHELF"]  # Shelf joint → BODY_25 joint (13 of them)
MIN_SHARED_JOINTS = 3  # a person is compared with an actor on at least this many joints


def one_to_one(pairs: list[tuple[float, int, int]]) -> list[tuple[int, int]]:
    """``(i, k)`` from candidate ``(distance, i, k)``: nearest pairs first, each ``i`` and
    each ``k`` taken once."""
    out, used_i, used_k = [], set(), set()
    for _, i, k in sorted(pairs):
        if i not in used_i and k not in used_k:
            out.append((i, k))
            used_i.add(i)
            used_k.add(k)
    return out


def assign_people(people: list[np.ndarray], uv: dict[int, np.ndarray], radius: float) -> dict:
    """``{actor: person index}`` in one view: nearest pairs first, one each.

    ``people``: the view's people ``(25, 3)`` (x, y px, score; 0: no detection); ``uv``:
    ``{actor: (15, 2)}`` the actor's annotated joints projected (NaN: not in the image)."""
    pairs = []
    for a, proj in uv.items():
        for k, person in enumerate(people):
            d = [
                np.linalg.norm(person[b, :2] - proj[s])
                for s, b in ANNOTATED.items()
                if person[b, 2] > 0 and np.all(np.isfinite(proj[s]))
            ]
            if len(d) >= MIN_SHARED_JOINTS and np.median(d) <= radius:
                pairs.append((float(np.median(d)), a, k))
    return dict(one_to_one(pairs))


def nearest_pairs(at: list[np.ndarray], dets: np.ndarray, radius: float) -> list[tuple[int, int]]:
    """One-to-one ``(i, k)``: point ``at[i] (2,)`` takes detection ``dets[k]`` (``(n, 2)``
    px), nearest pairs first, each within ``radius`` px (a NaN point takes none)."""
    return one_to_one(
        [
            (float(np.linalg.norm(dets[k] - p)), i, k)
            for i, p in enumerate(at)
            for k in range(len(dets))
            if np.linalg.norm(dets[k] - p) <= radius
        ]
    )


def ceiling_tracks(views, gt, K, R, t, size, frames, radius: float, by_joint: bool):
    """The ground truth's grouping as tracks for :func:`cdog_jax.triangulate`:
    ``xy (M, T, 2)`` px, ``mask (M, T)`` and ``keys``: ``(frame, actor, BODY_25 joint)`` of
    each track ``T``. ``views[m][f]``: view ``m``'s people in frame ``f`` (``(25, 3)`` each);
    the rest as :func:`shelf_detections.detection_stats`."""
    M, (W, H) = len(views), size
    keys, xy, mask = [], [], []
    for f in frames:
        actors = {a: j for a, j in gt[f].items() if a in shelf_score["ACTORS"]}
        chosen = np.zeros((len(actors), 25, M, 2))
        seen = np.zeros((len(actors), 25, M), bool)
        for m in range(M):
            uv = {}
            for a, joints in actors.items():
                p, depth = shelf_detections["project"](K[m], R[m], t[m], joints)
                inside = (depth > 0) & (p[:, 0] >= 0) & (p[:, 0] < W) & (p[:, 1] >= 0)
                uv[a] = np.where((inside & (p[:, 1] < H))[:, None], p, np.nan)
            people = views[m][f]
            owner = assign_people(people, uv, radius)
            for i, a in enumerate(actors):
                if a in owner:
                    person = people[owner[a]]
                    seen[i, :, m] = person[:, 2] > 0
                    chosen[i, :, m] = person[:, :2]
            if not by_joint:
                continue
            for s, b in ANNOTATED.items():
                dets = np.array([p[b, :2] for p in people if p[b, 2] > 0]).reshape(-1, 2)
                seen[:, b, m] = False
                for i, k in nearest_pairs([uv[a][s] for a in actors], dets, radius):
                    seen[i, b, m] = True
                    chosen[i, b, m] = dets[k]
        for i, a in enumerate(actors):
            for b in range(25):
                keys.append((f, a, b))
                xy.append(chosen[i, b])
                mask.append(seen[i, b])
    xy = np.array(xy).reshape(-1, M, 2).transpose(1, 0, 2)
    return xy, np.array(mask).reshape(-1, M).T, keys


def ceiling_people(rig, views, gt, K, R, t, size, frames, radius: float, by_joint: bool):
    """``people[f]``: the triangulated actors of frame ``f`` as BODY_25 ``(25, 3)`` (NaN
    where fewer than two views hold the joint), a list over every frame of ``gt``."""
    xy, mask, keys = ceiling_tracks(views, gt, K, R, t, size, frames, radius, by_joint)
    points, ok = cdog_jax.triangulate(rig, jnp.asarray(xy, rig.K.dtype), jnp.asarray(mask))
    points, ok = np.asarray(points, float), np.asarray(ok)
    found: dict[tuple[int, int], np.ndarray] = {}
    for (f, a, b), p, good in zip(keys, points, ok):
        body = found.setdefault((f, a), np.full((25, 3), np.nan))
        if good:
            body[b] = p
    people: list[list[np.ndarray]] = [[] for _ in gt]
    for (f, _), body in sorted(found.items()):
        if np.any(np.isfinite(body)):
            people[f].append(body)
    return people


def main(argv: list[str] | None = None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "data", help="a local copy of the 4D-association repository's data/shelf folder"
    )
    parser.add_argument("--split", choices=("dev", "held-out", "all"), default="dev")
    parser.add_argument("--radius", type=float, default=40.0, help="px (default 40)")
    parser.add_argument("--json", help="also write the rows here")
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    K, R, t, size, views, gt = shelf_detections["read_views"](args.data)
    count = min(len(gt), *(len(v) for v in views))
    gt = gt[:count]
    frames = shelf.split_frames(count, args.split)
    rig = cdog_jax.rig_from_arrays(K, R, t)
    rows = []
    for name, by_joint in (("by person", False), ("by joint", True)):
        people = ceiling_people(rig, views, gt, K, R, t, size, frames, args.radius, by_joint)
        row = shelf_score["score_skeletons"]([dict(enumerate(p)) for p in people], gt, frames)
        row["setting"] = f"the ground truth's grouping, {name}"
        rows.append(row)
        actors = " / ".join(f"{row['pcp'].get(f'actor {a}', float('nan')):.1f}" for a in (1, 2, 3))
        print(
            f"{row['setting']} ({args.split}, radius {args.radius:g} px): PCP {actors}, "
            f"mean {row['pcp_mean']:.1f}; recall@10cm {row['recall_10cm']:.3f}; "
            f"MPJPE {row['mpjpe_mm']:.1f} mm"
        )
        print("  parts: " + ", ".join(f"{k} {v:.1f}" for k, v in row["pcp_parts"].items()))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)
    return rows


if __name__ == "__main__":
    main()
