"""Shelf as a user meets it: real OpenPose detections of people, through the command line.

Shelf (Belagiannis et al. 2014): 5 calibrated cameras over a shelf, 3–4 actors; the copy read
here is the 301-frame clip of the 4D-association repository (public, github.com/
zhangyux15/4d_association, folder ``data/shelf``: ``calibration.json``, ``detection/0.txt`` …
``4.txt`` with OpenPose BODY_25 candidates and part-affinity (PAF) scores per view, ``gt.txt``
with the actors' 3D joints; nothing of it is committed here). Clone that repository (or
download the folder) and pass the path of ``data/shelf``.

What the script does, as a user with OpenPose output would:

1. reads the calibration (``K``, world-to-camera ``[R | t]``, image size) and writes it as
   the project's rig JSON;
2. reads each view's BODY_25 candidates (coordinates in [0, 1] of the image, scaled to
   pixels as the repository's own evaluation does: ``x · (W − 1)``) and PAF scores, and
   parses each view's candidates into people as OpenPose does (:func:`parse_people`:
   limb by limb in OpenPose's order, each limb's candidate pairs greedily by PAF score,
   one-to-one; a pair joins the person holding either end, or merges two partial
   people that share no joint, or starts a person; people with fewer than
   ``MIN_PERSON_JOINTS`` joints are dropped);
3. writes one OpenPose JSON folder per camera (``pose/0/000000_keypoints.json`` …);
4. runs ``cdog-jax associate --rig rig.json --points pose --keypoints BODY_25 --out
   result.npz`` (plus any options given after ``--``), timed as a whole command;
5. scores the 3D points against ``gt.txt`` (:mod:`shelf_score`).

    python experiments/real/shelf.py PATH/TO/data/shelf                 # defaults
    python experiments/real/shelf.py PATH/TO/data/shelf -- --method paper
    python experiments/real/shelf.py PATH/TO/data/shelf --work /tmp/shelf --frames 50

Frames split in alternating blocks of 25: the even blocks (0–24, 50–74, …) are the
development frames, the odd blocks held out; the command runs on every frame (it reads no
labels) and ``--split`` says which frames are scored.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from shelf_score import score  # noqa: E402

NUM_JOINTS = 25  # OpenPose BODY_25
# BODY_25's PAF channels in the order the candidate files store them: (joint a, joint b).
PAF_PAIRS = (
    (1, 8),
    (9, 10),
    (10, 11),
    (8, 9),
    (8, 12),
    (12, 13),
    (13, 14),
    (1, 2),
    (2, 3),
    (3, 4),
    (2, 17),
    (1, 5),
    (5, 6),
    (6, 7),
    (5, 18),
    (1, 0),
    (0, 15),
    (0, 16),
    (15, 17),
    (16, 18),
    (14, 19),
    (19, 20),
    (14, 21),
    (11, 22),
    (22, 23),
    (11, 24),
)
# OpenPose's order of limbs when it assembles people (from the neck outwards).
LIMB_ORDER = (
    (1, 8),
    (1, 2),
    (1, 5),
    (2, 3),
    (3, 4),
    (5, 6),
    (6, 7),
    (8, 9),
    (9, 10),
    (10, 11),
    (8, 12),
    (12, 13),
    (13, 14),
    (1, 0),
    (0, 15),
    (15, 17),
    (0, 16),
    (16, 18),
    (2, 17),
    (5, 18),
    (14, 19),
    (19, 20),
    (14, 21),
    (11, 22),
    (22, 23),
    (11, 24),
)
MIN_PERSON_JOINTS = 3  # OpenPose drops people of fewer joints


class Frame:
    """One view's candidates in one frame: ``joints[j] (n_j, 3)`` rows ``x, y, score``
    (pixels) and ``pafs[k] (n_a, n_b)`` the PAF score of each candidate pair of
    ``PAF_PAIRS[k]``."""

    def __init__(self, joints: list[np.ndarray], pafs: list[np.ndarray]):
        self.joints, self.pafs = joints, pafs


def read_calibration(
    path: str,
) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray, tuple[int, int]]:
    """``calibration.json``: camera names (in numeric order), ``K (M, 3, 3)``, ``R (M, 3, 3)``,
    ``t (M, 3)`` (world to camera, metres) and the image size ``(width, height)``."""
    with open(path) as f:
        cams = json.load(f)
    names = sorted(cams, key=int)
    K = np.array([np.reshape(cams[n]["K"], (3, 3)) for n in names], float)
    RT = np.array([np.reshape(cams[n]["RT"], (3, 4)) for n in names], float)
    sizes = {tuple(int(v) for v in cams[n]["imgSize"]) for n in names}
    if len(sizes) != 1:
        raise ValueError(f"{path}: cameras of different image sizes {sorted(sizes)}")
    return names, K, RT[:, :, :3], RT[:, :, 3], sizes.pop()


def read_candidates(path: str, image_size: tuple[int, int]) -> list[Frame]:
    """A view's ``detection/<v>.txt``: a header ``type frames`` (type 4: BODY_25), then per
    frame, per joint, the candidate count ``n`` and three rows of ``n`` numbers (x, y in
    [0, 1] of the image, score), then per PAF channel an ``n_a × n_b`` matrix."""
    with open(path) as f:
        tokens = f.read().split()
    kind, frames = int(tokens[0]), int(tokens[1])
    if kind != 4:
        raise ValueError(f"{path}: skeleton type {kind}; this reader knows BODY_25 (4)")
    values = np.asarray(tokens[2:], float)
    scale = np.array([image_size[0] - 1, image_size[1] - 1, 1.0])
    at, out = 0, []
    for _ in range(frames):
        joints = []
        for _ in range(NUM_JOINTS):
            n = int(values[at])
            joints.append(values[at + 1 : at + 1 + 3 * n].reshape(3, n).T * scale)
            at += 1 + 3 * n
        pafs = []
        for a, b in PAF_PAIRS:
            size = len(joints[a]) * len(joints[b])
            pafs.append(values[at : at + size].reshape(len(joints[a]), len(joints[b])))
            at += size
        out.append(Frame(joints, pafs))
    if at != len(values):
        raise ValueError(f"{path}: {len(values) - at} numbers left after {frames} frames")
    return out


def read_skeletons(path: str) -> list[dict[int, np.ndarray]]:
    """``gt.txt`` or ``skel.txt``: a header ``joints frames``, then per frame the number of
    people and per person its id and a ``4 × joints`` block (x, y, z in metres, then a
    weight row). Returns per frame ``{id: (joints, 3)}``."""
    with open(path) as f:
        tokens = f.read().split()
    J, frames = int(tokens[0]), int(tokens[1])
    at, out = 2, []
    for _ in range(frames):
        people = {}
        for _ in range(int(tokens[at])):
            pid = int(tokens[at + 1])
            block = np.asarray(tokens[at + 2 : at + 2 + 4 * J], float).reshape(4, J)
            people[pid] = block[:3].T
            at += 1 + 4 * J
        at += 1
        out.append(people)
    if at != len(tokens):
        raise ValueError(f"{path}: {len(tokens) - at} numbers left after {frames} frames")
    return out


def parse_people(frame: Frame) -> list[np.ndarray]:
    """One view's candidates parsed into people as OpenPose assembles them: each person a
    ``(25,)`` int array of candidate indices per joint (-1: none).

    Limbs in :data:`LIMB_ORDER`; within a limb, candidate pairs of positive PAF score (both
    candidates scored > 0) by decreasing score, each candidate used once per limb. A pair
    whose ends are both free starts a person; one end's person takes the other end if it
    has none of that joint; ends in two people merge them when they share no joint."""
    paf_of = {pair: k for k, pair in enumerate(PAF_PAIRS)}
    people: list[np.ndarray] = []
    owner = [np.full(len(c), -1) for c in frame.joints]  # candidate -> person
    for a, b in LIMB_ORDER:
        scores = frame.pafs[paf_of[(a, b)]]
        ca, cb = frame.joints[a], frame.joints[b]
        pairs = [
            (scores[i, j], i, j)
            for i in range(len(ca))
            for j in range(len(cb))
            if scores[i, j] > 0 and ca[i, 2] > 0 and cb[j, 2] > 0
        ]
        used_a, used_b = set(), set()
        for _, i, j in sorted(pairs, key=lambda p: -p[0]):
            if i in used_a or j in used_b:
                continue
            used_a.add(i)
            used_b.add(j)
            pa, pb = owner[a][i], owner[b][j]
            if pa < 0 and pb < 0:
                person = np.full(NUM_JOINTS, -1)
                person[a], person[b] = i, j
                owner[a][i] = owner[b][j] = len(people)
                people.append(person)
            elif pb < 0 or pa < 0:
                p, joint, cand = (pa, b, j) if pb < 0 else (pb, a, i)
                if people[p][joint] < 0:
                    people[p][joint] = cand
                    owner[joint][cand] = p
            elif pa != pb and not np.any((people[pa] >= 0) & (people[pb] >= 0)):
                keep, gone = min(pa, pb), max(pa, pb)
                taken = people[gone] >= 0
                people[keep][taken] = people[gone][taken]
                people[gone][:] = -1
                for joint in np.flatnonzero(taken):
                    owner[joint][people[keep][joint]] = keep
    return [p for p in people if np.sum(p >= 0) >= MIN_PERSON_JOINTS]


def person_keypoints(frame: Frame, person: np.ndarray) -> list[float]:
    """OpenPose's ``pose_keypoints_2d``: ``x, y, score`` per joint, zeros where none."""
    out = np.zeros((NUM_JOINTS, 3))
    for j, c in enumerate(person):
        if c >= 0:
            out[j] = frame.joints[j][c]
    return [float(v) for v in out.reshape(-1)]


def write_openpose(views: list[list[Frame]], folder: str) -> None:
    """One folder per view of one ``<frame>_keypoints.json`` per frame, as OpenPose writes."""
    for v, frames in enumerate(views):
        cam = os.path.join(folder, str(v))
        os.makedirs(cam, exist_ok=True)
        for f, frame in enumerate(frames):
            people = [
                {"person_id": [-1], "pose_keypoints_2d": person_keypoints(frame, p)}
                for p in parse_people(frame)
            ]
            with open(os.path.join(cam, f"{f:06d}_keypoints.json"), "w") as out:
                json.dump({"version": 1.3, "people": people}, out)


def write_rig(path: str, K, R, t, image_size) -> None:
    from cdog_jax import rig_from_arrays
    from cdog_jax.io import save_rig

    save_rig(path, rig_from_arrays(K, R, t), format="json", image_size=image_size)


def prepare(data: str, work: str, frames: int | None = None) -> dict:
    """Read ``data`` (a ``data/shelf`` folder), write the rig and the OpenPose folders under
    ``work``; returns the paths and the ground truth."""
    names, K, R, t, size = read_calibration(os.path.join(data, "calibration.json"))
    views = [read_candidates(os.path.join(data, "detection", f"{n}.txt"), size) for n in names]
    gt = read_skeletons(os.path.join(data, "gt.txt"))
    count = min(len(gt), *(len(v) for v in views))
    if frames is not None:
        count = min(count, frames)
    os.makedirs(work, exist_ok=True)
    rig, pose = os.path.join(work, "rig.json"), os.path.join(work, "pose")
    write_rig(rig, K, R, t, size)
    write_openpose([v[:count] for v in views], pose)
    return {"rig": rig, "pose": pose, "gt": gt[:count], "frames": count}


def run_command(rig: str, pose: str, out: str, extra: list[str]) -> float:
    """``cdog-jax associate`` as a user runs it; returns its wall time (s)."""
    cmd = [
        sys.executable,
        "-m",
        "cdog_jax",
        "associate",
        "--rig",
        rig,
        "--points",
        pose,
        "--keypoints",
        "BODY_25",
        "--out",
        out,
        *extra,
    ]
    start = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"cdog-jax associate failed ({done.returncode}): {done.stderr.strip()}")
    return seconds


def split_frames(count: int, split: str) -> np.ndarray:
    """Frame indices of ``split``: ``dev`` the even blocks of 25, ``held-out`` the odd ones,
    ``all`` every frame. A last block shorter than 25 joins the one before (Shelf's frame
    300 is held out with 275–299)."""
    frames = np.arange(count)
    if split == "all":
        return frames
    block = np.minimum(frames // 25, max(count // 25 - 1, 0))
    even = block % 2 == 0
    return frames[even] if split == "dev" else frames[~even]


def main(argv: list[str] | None = None) -> dict:
    argv = sys.argv[1:] if argv is None else argv
    extra = argv[argv.index("--") + 1 :] if "--" in argv else []
    argv = argv[: argv.index("--")] if "--" in argv else argv
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "data", help="a local copy of the 4D-association repository's data/shelf folder"
    )
    parser.add_argument(
        "--work",
        default=os.path.join(os.path.expanduser("~"), ".cache", "cdog_jax", "shelf"),
        help="where the rig, the OpenPose folders and the result go",
    )
    parser.add_argument("--frames", type=int, default=None, help="only the first N frames")
    parser.add_argument(
        "--split", choices=("dev", "held-out", "all"), default="dev", help="frames scored"
    )
    parser.add_argument("--json", default=None, help="also write the scores to this JSON file")
    args = parser.parse_args(argv)
    ready = prepare(args.data, args.work, args.frames)
    out = os.path.join(args.work, "result.npz")
    seconds = run_command(ready["rig"], ready["pose"], out, extra)
    scored = split_frames(ready["frames"], args.split)
    with np.load(out) as result:
        report = score(dict(result), ready["gt"], scored)
    report.update(
        command_s=round(seconds, 2),
        frames=ready["frames"],
        split=args.split,
        options=" ".join(extra),
    )
    print(json.dumps(report, indent=1))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(report, f, indent=1)
    return report


if __name__ == "__main__":
    main()
