"""Track ids and the temporal prior on walking people (docs/ALGORITHM.md §19).

Question: on sequences of 3–5 walking people in 5 views with the tails of real detections
(Student-t ν = 2.5, σ = 5.21 px, as fitted in ``robustness_realistic.py``), and some joints
dropped in some views, what do 3D recall within 10 cm, the share of groups joining two
people's joints and the identity switches per track become with the temporal prior, for
every preset?

Method:

- ``ring_rig()`` (5 views, 1920×1080, f = 1200 px, 5 m ring); ``generate_skeleton_scenes``
  at 10 fps, ``--sequences`` sequences of ``--frames`` frames, people 3, 4, 5 in turn.
- Dropped joints: in every frame each person's joint is, with probability ``--drop``
  (default 0.2), kept in only 2 of the views that see it (its other detections masked), so
  a frame may hold a joint seen in too few views, or in two views only, that the
  association cannot confirm.
- Every frame associated by ``associate_classes`` (σ estimated, pooled per frame) once per
  preset; then ``track_groups`` links the groups of every sequence, without and with
  ``temporal_prior=True`` (default gates: 60 px step, the frame's τ as the error gate), and
  with the prior and ``max_gap=1`` (a track may skip one frame).
- Recall: share of true joints with ≥ 2 real detections left that have a group of their
  class within 10 cm. Joining: groups with members of ≥ 2 true joints over all groups.
  A group's true joint: the most common true joint among its members. Identity switches:
  over every track, the number of times its true joint changes from one appearance to the
  next, over the number of tracks. Tracks per joint: distinct track ids a true joint gets
  over its sequence (1 is ideal; each break of a track adds one).

Usage::

    python experiments/temporal_prior.py [--sequences 6] [--frames 10] [--drop 0.2] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import time
from types import SimpleNamespace

import jax
import numpy as np

from cdog_jax import associate_classes, track_groups
from cdog_jax.synthetic import SKELETON_JOINTS, Realism, generate_skeleton_scenes, ring_rig

PRESETS = ("paper", "extended", "best")
CONDITIONS = ((False, 0), (True, 0), (True, 1))  # (temporal_prior, max_gap)
QUICK_CONDITIONS = (
    (False, 0),
    (True, 1),
)  # --quick: without and with the prior (each condition compiles its own tracker)
NU, SIGMA_PX, RADIUS_M = 2.5, 5.21, 0.1
SEED = 0


def sequences(num_sequences: int, frames: int, drop: float, seed: int = SEED):
    """The rig, every sequence's frames (a RealScene's fields ``(F, …)``, NumPy) with joints dropped, and the
    share of real detections dropped."""
    rig = ring_rig()
    rng = np.random.default_rng(seed)
    out, before, after = [], 0, 0
    for q in range(num_sequences):
        people = (3, 4, 5)[q % 3]
        sk = generate_skeleton_scenes(
            jax.random.fold_in(jax.random.PRNGKey(seed), q),
            rig,
            people,
            SIGMA_PX,
            realism=Realism(nu=NU),
            num_frames=frames,
            max_people=5,
        )
        fr = jax.tree.map(np.asarray, sk.frames)
        mask = fr.mask.copy()
        for f in range(frames):
            for point in np.unique(fr.instance[f][mask[f] & (fr.kind[f] == 0)]):
                if rng.random() < drop:
                    views = np.flatnonzero(np.any(mask[f] & (fr.instance[f] == point), axis=1))
                    for m in rng.permutation(views)[2:]:
                        mask[f, m] &= fr.instance[f, m] != point
        before, after = (
            before + int((fr.mask & (fr.kind == 0)).sum()),
            after + int((mask & (fr.kind == 0)).sum()),
        )
        out.append(
            SimpleNamespace(
                **{**{k: getattr(fr, k) for k in fr.__dataclass_fields__}, "mask": mask}
            )
        )
    return rig, out, 1.0 - after / max(before, 1)


def true_joint_of_groups(labels, valid, instance, mask):
    """``(G,)`` the most common true joint among each valid group's members (-1: none), and
    ``(G,)`` whether the group holds ≥ 2 true joints."""
    G = valid.shape[0]
    joint, joined = np.full(G, -1), np.zeros(G, bool)
    for g in np.flatnonzero(valid):
        ids = instance[mask & (labels == g)]
        ids = ids[ids >= 0]
        if ids.size:
            values, counts = np.unique(ids, return_counts=True)
            joint[g], joined[g] = values[np.argmax(counts)], values.size >= 2
    return joint, joined


def score(tracked, fr, rig_frames):
    """Recall, joined groups, groups, switches, tracks and tracks per joint of one sequence."""
    a = tracked.association
    labels, valid, X = (np.asarray(v) for v in (a.labels, a.valid, a.points3d))
    cls, tid = np.asarray(tracked.group_class), np.asarray(tracked.track_id)
    J = len(SKELETON_JOINTS)
    hit = total = joined = groups = 0
    joint_of = {}  # track → [true joint per appearance]
    ids_of_joint: dict[int, set] = {}
    for f in range(rig_frames):
        real = fr.mask[f] & (fr.kind[f] == 0)
        seen = np.bincount(fr.instance[f][real], minlength=fr.points3d.shape[1]) >= 2
        for i in np.flatnonzero(seen):
            ok = (
                valid[f]
                & (cls[f] == i % J)
                & (np.linalg.norm(X[f] - fr.points3d[f, i], axis=1) <= RADIUS_M)
            )
            hit, total = hit + int(ok.any()), total + 1
        joint, join = true_joint_of_groups(labels[f], valid[f], fr.instance[f], fr.mask[f])
        joined, groups = joined + int(join.sum()), groups + int(valid[f].sum())
        for g in np.flatnonzero(valid[f]):
            joint_of.setdefault(int(tid[f, g]), []).append(int(joint[g]))
            if joint[g] >= 0:
                ids_of_joint.setdefault(int(joint[g]), set()).add(int(tid[f, g]))
    switches = sum(
        sum(1 for a_, b_ in zip(js, js[1:]) if a_ >= 0 and b_ >= 0 and a_ != b_)
        for js in joint_of.values()
    )
    per_joint = [len(s) for s in ids_of_joint.values()]
    return dict(
        hit=hit,
        total=total,
        joined=joined,
        groups=groups,
        switches=switches,
        tracks=len(joint_of),
        joint_tracks=sum(per_joint),
        joints=len(per_joint),
        recovered=int(np.asarray(tracked.recovered).sum()),
    )


def run(
    *,
    num_sequences=6,
    frames=10,
    drop=0.2,
    presets=PRESETS,
    conditions=CONDITIONS,
    seed=SEED,
    log=print,
):
    t0 = time.perf_counter()
    rig, seqs, dropped_share = sequences(num_sequences, frames, drop, seed)
    xy = np.concatenate([s.xy for s in seqs])
    mask = np.concatenate([s.mask for s in seqs])
    classes = np.concatenate([s.class_id for s in seqs])
    rows = []
    for preset in presets:
        result = associate_classes(
            rig, xy, mask, classes, class_names=SKELETON_JOINTS, method=preset, sigma="auto"
        )
        log(f"{preset}: associated {xy.shape[0]} frames, {time.perf_counter() - t0:.0f} s")
        for prior, gap in conditions:
            total = {}
            for q, s in enumerate(seqs):
                part = slice(q * frames, (q + 1) * frames)
                one = result._replace(
                    association=jax.tree.map(lambda v: v[part], result.association),
                    group_class=result.group_class[part],
                )
                tracked = track_groups(
                    rig,
                    one,
                    xy=s.xy,
                    mask=s.mask,
                    classes=s.class_id,
                    temporal_prior=prior,
                    max_gap=gap,
                )
                for k, v in score(tracked, s, frames).items():
                    total[k] = total.get(k, 0) + v
            rows.append(
                {
                    "preset": preset,
                    "prior": prior,
                    "max_gap": gap,
                    "recall": total["hit"] / max(total["total"], 1),
                    "joined": total["joined"] / max(total["groups"], 1),
                    "switches_per_track": total["switches"] / max(total["tracks"], 1),
                    "tracks_per_joint": total["joint_tracks"] / max(total["joints"], 1),
                    "recovered": total["recovered"],
                    "groups": total["groups"],
                }
            )
        log(f"{preset}: tracked, {time.perf_counter() - t0:.0f} s")
    return {
        "sequences": num_sequences,
        "frames": frames,
        "drop": drop,
        "nu": NU,
        "sigma": SIGMA_PX,
        "rows": rows,
        "dropped_share": dropped_share,
        "seconds": time.perf_counter() - t0,
    }


def markdown(out) -> str:
    lines = [
        f"{out['sequences']} sequences × {out['frames']} frames (10 fps) of 3–5 people, 5 views, ν = {out['nu']:g}, "
        f"σ = {out['sigma']:g} px, σ estimated; a joint kept in only 2 views with probability {out['drop']:g} per frame "
        f"({100 * out['dropped_share']:.1f} % of the real detections dropped):",
        "",
        "| preset | temporal prior | max gap | recall within 10 cm | groups joining two people's joints | identity switches per track "
        "| tracks per true joint | groups recovered |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in out["rows"]:
        lines.append(
            f"| {r['preset']} | {'on' if r['prior'] else 'off'} | {r['max_gap']} | {r['recall']:.3f} | {100 * r['joined']:.2f} % | "
            f"{r['switches_per_track']:.3f} | {r['tracks_per_joint']:.2f} | {r['recovered']} |"
        )
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sequences", type=int, default=6)
    parser.add_argument("--frames", type=int, default=10)
    parser.add_argument(
        "--drop",
        type=float,
        default=0.2,
        help="probability that a joint is kept in only 2 views in a frame",
    )
    parser.add_argument("--presets", nargs="+", choices=PRESETS, default=list(PRESETS))
    parser.add_argument("--seed", type=int, default=SEED)
    parser.add_argument("--json", default=None, help="also write the numbers here")
    parser.add_argument(
        "--quick",
        action="store_true",
        help="tiny run: 1 sequence of 3 frames, paper() only, the prior off and on with max_gap=1",
    )
    args = parser.parse_args(argv)
    if args.quick:
        args.sequences, args.frames, args.presets = 1, 3, ["paper"]
    out = run(
        num_sequences=args.sequences,
        frames=args.frames,
        drop=args.drop,
        presets=tuple(args.presets),
        conditions=QUICK_CONDITIONS if args.quick else CONDITIONS,
        seed=args.seed,
    )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)
    print(markdown(out))
    print(f"\ntotal {out['seconds']:.1f} s")
    return out


if __name__ == "__main__":
    main()
