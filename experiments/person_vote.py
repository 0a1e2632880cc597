"""The person-level vote (``associate_classes(..., instances=, person_vote=True)``) on skeleton
scenes with the tails fitted to real OpenPose detections.

Question: on scenes of 3–5 walking people in 5 views, Student-t tails ν = 2.5, σ = 5.21 px
(the fit of ``experiments/robustness_realistic.py``), how do the 3D recall within 10 cm and
the share of groups joining two people's joints change for every preset when the
detections carry a per-view instance index and the vote is on?

Method: ``robustness_realistic.skeleton_batch`` and ``score`` (the same scenes generator,
recall and joined share). The per-view instance index is what a 2D pose estimator gives:
in every frame and view the people are numbered by a random permutation (no identity across
views); a double detection belongs to a separate partial skeleton of its person (index
``K + `` its person's number), clutter has none (-1). σ is estimated (``sigma="auto"``).
Rows "+ doubles, clutter" add a double rate of 0.1 and 5 clutter detections per view.

Real data (``--pose2sim``, the Pose2Sim demo of ``experiments/real_pose2sim.py``, already
downloaded there): the two moving trials, OpenPose's person index of every view as the
instances, without and with the vote; no ground truth, so the table gives what moves (3D
points, assigned share, reprojection error, ``= visible`` as in ``real_pose2sim.py``) and
how many detections change group.

Usage::

    python experiments/person_vote.py [--sequences 6] [--frames 4] [--json out.json] [--quick]
        [--pose2sim ~/.cache/cdog_jax/pose2sim-0.7.2/S00_Demo_Session]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import time

import numpy as np

from cdog_jax import associate_classes
from cdog_jax.synthetic import SKELETON_JOINTS, Realism

PRESETS = ("paper", "extended", "reference", "best")
NU, SIGMA = 2.5, 5.21  # the tails fitted in robustness_realistic.py (RESULTS.md)
MAX_PEOPLE = 5
SEED = 0


def _load_script(name: str):
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), name)
    spec = importlib.util.spec_from_file_location(os.path.splitext(name)[0], path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def per_view_instances(frames, seed: int) -> np.ndarray:
    """``(F, M, S)`` per-view instance index: a random permutation of the people in every
    frame and view; a double gets ``MAX_PEOPLE +`` its person's number, clutter -1."""
    J = len(SKELETON_JOINTS)
    inst, kind, mask = (np.asarray(a) for a in (frames.instance, frames.kind, frames.mask))
    F, M, _ = mask.shape
    rng = np.random.default_rng(seed)
    order = np.argsort(rng.random((F, M, MAX_PEOPLE)), axis=-1)  # person -> its number in the view
    person = np.where(inst >= 0, inst // J, 0)
    number = np.take_along_axis(order, person, axis=-1)
    out = np.where(kind == 1, MAX_PEOPLE + number, number)
    return np.where(mask & (inst >= 0), out, -1)


def _seconds(call) -> float:
    t = time.perf_counter()
    call()
    return time.perf_counter() - t


def run(*, sequences=6, frames=4, presets=PRESETS, seed=SEED, extras=True, log=print):
    rr = _load_script("robustness_realistic.py")
    family = dict(rr.FAMILIES["skeleton"], sigma=SIGMA)
    cases = {"targets": Realism(nu=NU)}
    if extras:
        cases["+ doubles, clutter"] = Realism(nu=NU, double_rate=0.1, clutter_rate=5.0)
    t0 = time.perf_counter()
    out = {"nu": NU, "sigma": SIGMA, "sequences": sequences, "frames": frames, "rows": []}
    for case, opts in cases.items():
        rig, batch = rr.skeleton_batch(
            [("tails", NU)], sequences, frames, family, seed + 11, people=(3, 4, 5), realism_of=opts
        )
        instances = per_view_instances(batch, seed)
        point_class = np.arange(batch.points3d.shape[1]) % len(SKELETON_JOINTS)
        for preset in presets:
            warm = {}
            for vote in (False, True):

                def call(vote=vote, preset=preset):
                    return associate_classes(
                        rig,
                        batch.xy,
                        batch.mask,
                        batch.class_id,
                        class_names=SKELETON_JOINTS,
                        method=preset,
                        instances=instances if vote else None,
                        person_vote=vote,
                    )

                t = time.perf_counter()
                res = call()
                seconds = time.perf_counter() - t
                # The vote's cost: a warm call with it less a warm call without it (both
                # compiled by the calls above; the fastest of three each), per frame.
                warm[vote] = min(_seconds(call) for _ in range(3))
                step_ms = 1e3 * (warm[True] - warm[False]) / batch.xy.shape[0] if vote else 0.0
                s = rr.score(
                    rig,
                    res.association,
                    batch,
                    point_class,
                    res.group_class,
                    family["radius"],
                    family["sigma"],
                )
                out["rows"].append(
                    {
                        "case": case,
                        "preset": preset,
                        "vote": vote,
                        "recall": float(np.nanmean(s["recall"])),
                        "joined": float(s["joined"].sum() / max(s["groups"].sum(), 1)),
                        "pg_f1": float(np.mean(s["pg_f1"])),
                        "seconds": seconds,
                        "vote_ms_per_frame": step_ms,
                    }
                )
                log(
                    f"{case} {preset} vote={vote}: {out['rows'][-1]}, {time.perf_counter() - t0:.0f} s"
                )
        out.setdefault("frames_total", int(batch.xy.shape[0]))
    out["seconds"] = time.perf_counter() - t0
    return out


def _members(assoc, f):
    """``{(view, slot): frozenset of its group's (view, slot)}`` of frame ``f``."""
    groups, valid = np.asarray(assoc.groups[f]), np.asarray(assoc.valid[f])
    out = {}
    for g in groups[valid]:
        members = frozenset((m, int(x)) for m, x in enumerate(g) if x >= 0)
        out.update({k: members for k in members})
    return out


def run_pose2sim(demo: str, presets=("paper", "extended", "best"), log=print):
    """The moving trials of the Pose2Sim demo, without and with the vote (σ estimated)."""
    import jax

    from cdog_jax.io import load_openpose, load_rig

    rp = _load_script("real_pose2sim.py")
    calib, trials = rp.find_inputs(demo)
    rig_file = load_rig(calib)
    dist = rig_file.dist if rig_file.dist is not None and np.any(rig_file.dist) else None
    rows = []
    for name, pose, participants in trials:
        if "Static" in name:
            continue
        det = load_openpose(
            pose,
            keypoints="BODY_25B",
            num_views=rig_file.rig.num_views,
            image_size=rig_file.image_size,
        )
        for preset in presets:
            res = {}
            for vote in (False, True):
                t = time.perf_counter()
                res[vote] = associate_classes(
                    rig_file.rig,
                    det.xy.astype(np.float32),
                    det.mask,
                    det.classes,
                    class_names=det.class_names,
                    method=preset,
                    dist=dist,
                    instances=det.instances if vote else None,
                    person_vote=vote,
                )
                jax.block_until_ready(res[vote].association.points3d)
                stats = rp.trial_stats(det, res[vote], participants)
                stats.update(
                    trial=name,
                    people=participants,
                    preset=preset,
                    vote=vote,
                    seconds=time.perf_counter() - t,
                )
                rows.append(stats)
            F = det.mask.shape[0]
            moved = sum(
                sum(a.get(k) != b.get(k) for k in set(a) | set(b))
                for a, b in (
                    (_members(res[False].association, f), _members(res[True].association, f))
                    for f in range(F)
                )
            )
            rows[-1]["moved"] = int(moved)
            log(
                f"pose2sim {name} {preset}: {rows[-2]['points']} → {rows[-1]['points']} points, {moved} detections change group"
            )
    return rows


def markdown_pose2sim(rows) -> str:
    lines = [
        "| trial | people | preset | 3D points (off → vote) | assigned | err median (px) | err p90 (px) | = visible "
        "| detections that change group |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for a, b in zip(rows[0::2], rows[1::2]):
        lines.append(
            f"| {a['trial']} | {a['people']} | {a['preset']} | {a['points']} → {b['points']} | "
            f"{a['assigned'] / a['detections']:.3f} → {b['assigned'] / b['detections']:.3f} | "
            f"{a['err_median']:.1f} → {b['err_median']:.1f} | {a['err_p90']:.1f} → {b['err_p90']:.1f} | "
            f"{a['visible_exact']:.3f} → {b['visible_exact']:.3f} | {b['moved']} of {a['detections']} |"
        )
    return "\n".join(lines)


def markdown(out) -> str:
    lines = [
        f"Skeleton scenes of 3–5 people, 5 views, ν = {out['nu']:g}, σ = {out['sigma']:.2f} px, σ estimated "
        f"({out['frames_total']} frames: {out['sequences']} sequences × {out['frames']}):",
        "",
        "| scenes | preset | recall within 10 cm (off → vote) | groups joining two people (off → vote) | PG-F1 (off → vote) "
        "| vote step (ms/frame) |",
        "|---|---|---|---|---|---|",
    ]
    rows = {(r["case"], r["preset"], r["vote"]): r for r in out["rows"]}
    for case, preset, vote in rows:
        if vote:
            continue
        a, b = rows[case, preset, False], rows[case, preset, True]
        lines.append(
            f"| {case} | {preset} | {a['recall']:.3f} → {b['recall']:.3f} | {100 * a['joined']:.2f} % → "
            f"{100 * b['joined']:.2f} % | {a['pg_f1']:.3f} → {b['pg_f1']:.3f} | {b['vote_ms_per_frame']:.1f} |"
        )
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--sequences", type=int, default=6, help="sequences (3, 4, 5 people in turn)"
    )
    parser.add_argument("--frames", type=int, default=4, help="frames per sequence")
    parser.add_argument("--presets", nargs="+", choices=PRESETS, default=list(PRESETS))
    parser.add_argument("--seed", type=int, default=SEED)
    parser.add_argument("--json", default=None, help="also write the numbers here")
    parser.add_argument(
        "--quick",
        action="store_true",
        help="tiny run: 1 sequence of 2 frames, paper() only, targets only",
    )
    parser.add_argument(
        "--pose2sim",
        default=None,
        help="also the Pose2Sim demo folder (S00_Demo_Session, unpacked)",
    )
    args = parser.parse_args(argv)
    extras = not args.quick
    if args.quick:
        args.sequences, args.frames, args.presets = 1, 2, ["paper"]
    out = run(
        sequences=args.sequences,
        frames=args.frames,
        presets=tuple(args.presets),
        seed=args.seed,
        extras=extras,
    )
    if args.pose2sim:
        t = time.perf_counter()
        out["pose2sim"] = run_pose2sim(
            args.pose2sim, presets=tuple(p for p in args.presets if p != "reference")
        )
        out["seconds_pose2sim"] = time.perf_counter() - t
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)
    print(markdown(out))
    if args.pose2sim:
        print("\nPose2Sim demo, σ estimated:\n\n" + markdown_pose2sim(out["pose2sim"]))
    print(f"\ntotal {out['seconds'] + out.get('seconds_pose2sim', 0.0):.1f} s")
    return out


if __name__ == "__main__":
    main()
