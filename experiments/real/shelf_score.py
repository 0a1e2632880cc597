"""Shelf's scores: PCP over people as the field computes it, recall of joints within 10 cm, MPJPE.

Shelf's ground truth holds 15 joints per actor (the 14 of the original annotation and the hip
centre): 0 right ankle, 1 right knee, 2 right hip, 3 left hip, 4 left knee, 5 left ankle,
6 right wrist, 7 right elbow, 8 right shoulder, 9 left shoulder, 10 left elbow, 11 left
wrist, 12 bottom of the head (neck), 13 top of the head, 14 hip centre; metres, z up.

**PCP** (percentage of correct parts; Belagiannis et al., as mvpose and VoxelPose compute
it): per actor (ids 0–2 are actors 1–3) and frame where the actor is annotated, the
predicted person of smallest mean joint distance to the actor is matched; each of the 10
parts (upper and lower arms and legs, head, torso) is correct when the mean of its two
end-joint errors is at most ``ALPHA`` = 0.5 of the part's true length. A frame with no
predicted person scores no part. The score of an actor is the mean over its frames and
parts; the summary is the mean over actors 1–3.

**From BODY_25 to Shelf's joints** (:func:`shelf_from_body25`): the 12 limb joints and the
hip centre are OpenPose's joints of the same name; the neck and head top are made as the
4D-association repository's evaluation makes them from its skeleton: the neck half-way
between the shoulders' centre and the ears' centre, the head top 0.125 m along the face's
direction (the normal of the neck–hip and right–left shoulder vectors) and 0.145 m up
from it. A joint the person lacks is NaN, and a part with a NaN end is not correct.

**Recall@10cm**: the share of (actor, frame, limb joint) of the 12 limb joints with a
predicted 3D point of that joint type within 10 cm (any person: no identities needed).
**MPJPE**: the mean distance (mm) of the matched person's joints to the actor's, over the
joints both have.
"""

from __future__ import annotations

import numpy as np

ALPHA = 0.5
ACTORS = (0, 1, 2)  # the ground truth's ids of actors 1–3 (the field reports these)
RECALL_RADIUS_M = 0.1
# Shelf's 10 parts as (name, joint a, joint b) of the 15 ground-truth joints.
PARTS = (
    ("left upper arm", 9, 10),
    ("right upper arm", 8, 7),
    ("left lower arm", 10, 11),
    ("right lower arm", 7, 6),
    ("left upper leg", 3, 4),
    ("right upper leg", 2, 1),
    ("left lower leg", 4, 5),
    ("right lower leg", 1, 0),
    ("head", 12, 13),
    ("torso", 12, 14),
)
# BODY_25 joint for each of Shelf's joints 0–11 and 14 (12, 13 are made: see the docstring).
BODY25_OF_SHELF = {
    0: 11,
    1: 10,
    2: 9,
    3: 12,
    4: 13,
    5: 14,
    6: 4,
    7: 3,
    8: 2,
    9: 5,
    10: 6,
    11: 7,
    14: 8,
}
LIMB_JOINTS = tuple(range(12))
# The 4D-association repository's 19-joint skeleton (its skel.txt) in BODY_25 ids.
BODY25_OF_SKEL19 = (8, 1, 9, 12, 0, 2, 5, 10, 13, 17, 18, 3, 6, 11, 14, 4, 7, 19, 22)
NECK, NOSE, R_SHOULDER, L_SHOULDER, MID_HIP, R_EAR, L_EAR = 1, 0, 2, 5, 8, 17, 18


def body25_from_skel19(skel: np.ndarray) -> np.ndarray:
    """``(19, 3)`` joints of the 4D-association skeleton as ``(25, 3)`` BODY_25 joints (NaN
    for the six BODY_25 joints it lacks)."""
    out = np.full((25, 3), np.nan)
    out[list(BODY25_OF_SKEL19)] = skel
    return out


def shelf_from_body25(body: np.ndarray) -> np.ndarray:
    """``(25, 3)`` BODY_25 joints (metres, NaN: missing) as Shelf's ``(15, 3)`` joints."""
    shelf = np.full((15, 3), np.nan)
    for s, b in BODY25_OF_SHELF.items():
        shelf[s] = body[b]
    shoulders = 0.5 * (body[R_SHOULDER] + body[L_SHOULDER])
    ears = 0.5 * (body[R_EAR] + body[L_EAR])
    face = np.cross(body[NECK] - body[MID_HIP], body[R_SHOULDER] - body[L_SHOULDER])
    with np.errstate(invalid="ignore", divide="ignore"):
        face = face / np.linalg.norm(face)
    shelf[12] = shoulders + 0.5 * (ears - shoulders)
    shelf[13] = shelf[12] + 0.125 * face + np.array([0.0, 0.0, 0.145])
    return shelf


def correct_parts(pred: np.ndarray, true: np.ndarray) -> np.ndarray:
    """``(10,)`` bool: each part of ``pred (15, 3)`` correct against ``true (15, 3)``."""
    out = np.zeros(len(PARTS), bool)
    for k, (_, a, b) in enumerate(PARTS):
        length = np.linalg.norm(true[a] - true[b])
        err = 0.5 * (np.linalg.norm(pred[a] - true[a]) + np.linalg.norm(pred[b] - true[b]))
        out[k] = bool(np.isfinite(err) and err <= ALPHA * length)
    return out


def _mean_distance(pred: np.ndarray, true: np.ndarray) -> float:
    d = np.linalg.norm(pred - true, axis=-1)
    d = d[np.isfinite(d)]
    return float(d.mean()) if d.size else np.inf


def pcp(people: list[list[np.ndarray]], gt: list[dict[int, np.ndarray]], frames) -> dict:
    """PCP (module docstring) of predicted ``people[f]`` (a list of Shelf ``(15, 3)``
    skeletons per frame) on ``frames``; with the MPJPE of the matched (mm) and the count of
    scored (actor, frame) pairs. Returns ``{"pcp": {actor: %}, "pcp_parts": {part: %},
    "pcp_mean": %, "mpjpe_mm": mm, "scored": n}``."""
    hits: dict[int, list[np.ndarray]] = {a: [] for a in ACTORS}
    errors = []
    for f in frames:
        for actor, true in gt[f].items():
            if actor not in hits:
                continue
            candidates = people[f]
            if not candidates:
                hits[actor].append(np.zeros(len(PARTS), bool))
                continue
            distances = [_mean_distance(p, true) for p in candidates]
            best = candidates[int(np.argmin(distances))]
            hits[actor].append(correct_parts(best, true))
            d = np.linalg.norm(best[:14] - true[:14], axis=-1)
            errors.extend(d[np.isfinite(d)])
    per_actor = {a: 100.0 * float(np.mean(h)) for a, h in hits.items() if h}
    every = (
        np.concatenate([np.stack(h) for h in hits.values() if h])
        if any(hits.values())
        else np.zeros((0, len(PARTS)))
    )
    return {
        "pcp": {f"actor {a + 1}": round(v, 1) for a, v in per_actor.items()},
        "pcp_mean": round(float(np.mean(list(per_actor.values()))), 1) if per_actor else None,
        "pcp_parts": {
            name: round(100.0 * float(every[:, k].mean()), 1)
            for k, (name, _, _) in enumerate(PARTS)
        }
        if len(every)
        else {},
        "mpjpe_mm": round(1000.0 * float(np.mean(errors)), 1) if errors else None,
        "scored": int(sum(len(h) for h in hits.values())),
    }


def joint_recall(
    points: list[dict[int, np.ndarray]], gt: list[dict[int, np.ndarray]], frames
) -> float:
    """Recall@10cm (module docstring) of ``points[f][body25_joint] (n, 3)``: every predicted
    3D point of that joint type in frame ``f``."""
    found = total = 0
    for f in frames:
        for actor, true in gt[f].items():
            if actor not in ACTORS:
                continue
            for s in LIMB_JOINTS:
                total += 1
                cands = points[f].get(BODY25_OF_SHELF[s])
                if cands is not None and len(cands):
                    found += bool(
                        np.min(np.linalg.norm(cands - true[s], axis=-1)) <= RECALL_RADIUS_M
                    )
    return found / max(total, 1)


def points_by_joint(result: dict) -> list[dict[int, np.ndarray]]:
    """The 3D points of an association result file (NPZ: ``points3d (F, G, 3)``, ``valid``,
    ``group_class``) per frame and joint type."""
    out = []
    for xyz, valid, cls in zip(result["points3d"], result["valid"], result["group_class"]):
        out.append({int(c): xyz[valid & (cls == c)] for c in np.unique(cls[valid])})
    return out


def people_points(people: list[list[np.ndarray]]) -> list[dict[int, np.ndarray]]:
    """Every person's BODY_25 joints ``(25, 3)`` pooled per frame and joint type."""
    out = []
    for frame in people:
        joints = {}
        for j in range(25):
            pts = np.array([p[j] for p in frame if np.all(np.isfinite(p[j]))]).reshape(-1, 3)
            if len(pts):
                joints[j] = pts
        out.append(joints)
    return out


def score(result: dict, gt: list[dict[int, np.ndarray]], frames) -> dict:
    """Recall@10cm of an association result (see :func:`points_by_joint`), and PCP and MPJPE
    when it holds people (``people_points (F, N, 25, 3)``, NaN where a joint or a person is
    missing, as ``cdog-jax associate --out result.npz`` writes them for OpenPose folders)."""
    report = {"recall_10cm": round(joint_recall(points_by_joint(result), gt, frames), 4)}
    if "people_points" in result:
        people = [
            [shelf_from_body25(p) for p in frame if np.any(np.isfinite(p))]
            for frame in result["people_points"]
        ]
        report.update(pcp(people, gt, frames))
    return report


def score_skeletons(
    skeletons: list[dict[int, np.ndarray]], gt: list[dict[int, np.ndarray]], frames
) -> dict:
    """The scores of another system's people, ``skeletons[f] = {id: (25, 3) BODY_25}``."""
    people = [[shelf_from_body25(p) for p in frame.values()] for frame in skeletons]
    report = {
        "recall_10cm": round(
            joint_recall(people_points([list(f.values()) for f in skeletons]), gt, frames), 4
        )
    }
    report.update(pcp(people, gt, frames))
    return report
