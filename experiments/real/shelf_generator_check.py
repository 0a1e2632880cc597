"""Does the synthetic people generator predict Shelf? Each preset's recall@10cm of the 12 limb
joints, joint by joint (every (frame, joint type) a scene of its own, σ estimated per scene:
the path of ``shelf_per_joint.py``), on Shelf's real dev frames and on synthetic scenes made
to look like them.

The synthetic scenes: Shelf's own five cameras (``calibration.json``, 1032 × 776 px), moved
so that the generator's walking area (about the world origin) lies where Shelf's actors
stand; 3–5 people (Shelf's cameras see 2–6) walking for ``--frames`` frames at 25 frames
per second, in ``--sequences`` sequences. Their detections are rendered four ways:

- ``clean``: Gaussian noise of ``--sigma`` px (default 5: the σ that C-DOG's estimator finds
  on Shelf's dev frames is 5.2 px; the 10.4 px of ``shelf_detections.py`` are measured
  against the annotation, whose joints are not OpenPose's, and an offset common to every
  view does not show in the epipolar geometry) and nothing else, the generator as it was;
- ``+ view spread``: the views' σ spread as Shelf's (log spread 0.22);
- ``+ keypoint errors``: also :meth:`KeypointErrors.shelf` (joints missed, more often where
  a person hides them, left/right swaps);
- ``+ error tails``: also a share ``--tail-share`` (default 0.02) of detections with
  ``--tail-scale`` (default 10) times the noise, 50 px per coordinate: Shelf's joints found
  within 100 px of the annotation lie beyond 4.5 σ 3.1 % of the time (``shelf_detections.py
  --radius 100``), some of them the misplaced detections that the 50 px rates count as
  missed.

``--scored seen-by-every-camera`` counts, in recall and PCP, only the synthetic people that
every camera sees (at least 80 % of their limb joints in its image), as Shelf's annotated
actors are (245 of 246 dev (actor, frame), ``shelf_detections.py``); by default every
person counts, about half of them seen by four cameras or fewer.

``--nu`` makes the noise of every setting Student-t with that many degrees of freedom, the
spread of its bulk kept (``Realism.nu``): heavier tails at the same σ.

Recall on the synthetic scenes counts every existing person's limb joints (``--scored``:
those every camera sees), on Shelf the annotated actors'. A last line gives Shelf's PCP (10
parts, actors 0–2, :mod:`shelf_score`) of the people of ``--pcp-preset`` with the person
vote (each view's people numbered in a random order, as a 2D pose detector numbers them;
``identify_people``), beside ``--real-pcp``: the same on Shelf (``shelf_table.py``'s row
without the temporal prior). The check of the defaults work: each preset within 0.02 of
Shelf, PCP within 2 points.

    python experiments/real/shelf_generator_check.py PATH/TO/data/shelf [--real-json rows.json]

``--real-json`` reads the real rows from ``shelf_per_joint.py --out`` instead of running them.

Which stages does the generator overrate? ``--left-out ROWS`` (names of :data:`LEFT_OUT`,
comma-separated, or ``all``) runs a preset with one of its stages left out, joint by joint
on Shelf's dev frames and on the ``+ keypoint errors`` scenes, beside the preset itself
(which ``--presets`` must hold): what the stage is worth on each. A stage worth more on the
synthetic scenes than on Shelf is one whose difficulty the generator does not reproduce.

    python experiments/real/shelf_generator_check.py PATH/TO/data/shelf --left-out all

The robustness study on the fitted generator: ``--robustness`` runs, instead of the check's
four renderings, the scenes of the fitted generator (``fitted``: the views' σ spread, the
detector's errors, noise of ``--sigma`` px with ``--nu`` degrees of freedom) and the same
people (one draw) with one thing at a time made harder (:func:`robustness_settings`): half
and one and a half times the noise, twice the misses, 2 % swaps, 5 clutter detections per
view, 5 % doubles, cameras rotated 0.2° off, 6–8 people. The Shelf column stays the
``fitted`` setting's yardstick (the fitted generator is scored with ``--scored
seen-by-every-camera``, as below).

    python experiments/real/shelf_generator_check.py PATH/data/shelf --robustness --nu 3 --sigma 6
"""

from __future__ import annotations

import argparse
import json
import math
import os
import runpy
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
shelf = runpy.run_path(os.path.join(HERE, "shelf.py"), run_name="shelf")
shelf_score = runpy.run_path(os.path.join(HERE, "shelf_score.py"), run_name="shelf_score")
shelf_detections = runpy.run_path(
    os.path.join(HERE, "shelf_detections.py"), run_name="shelf_detections"
)

PRESETS = ("best", "extended", "paper", "reference")
SHELF_CENTRE = np.array([0.5, -0.2, 0.0])  # metres: the middle of Shelf's actors on the floor
LIMBS = tuple(range(5, 17))  # COCO-17's shoulders … ankles: Shelf's 12 limb joints
RECALL_RADIUS_M = 0.1

#: A preset with one stage or option left out: ``(preset, Config fields)``.
LEFT_OUT: dict[str, tuple[str, dict]] = {
    "best() − seed": ("best", {"seed": False}),
    "best() − reassign": ("best", {"reassign": False}),
    "best() − support_filter": ("best", {"support_filter": False}),
    "best() − recover": ("best", {"recover": False}),
    "best() − detach_ambiguous": ("best", {"detach_ambiguous": False}),
    "extended() − regroup": ("extended", {"regroup": False}),
    "extended() mutual adjacency": ("extended", {"adjacency": "mutual"}),
    "extended() − recover": ("extended", {"recover": False}),
    "extended() − IQR": ("extended", {"iqr": False}),
    "extended() − BPE filter": ("extended", {"bpe_filter": False}),
}


def robustness_settings(sigma: float, nu: float) -> dict[str, dict]:
    """The robustness study on the fitted generator: its scenes (``fitted``: the views' σ
    spread, :meth:`KeypointErrors.shelf`, noise of ``sigma`` px with ``nu`` degrees of
    freedom), then one thing at a time made harder. Each value: the keyword arguments of
    :func:`synthetic_scenes` beyond the rig, the size and the draw."""
    from cdog_jax.synthetic import KeypointErrors

    shelf_errors = KeypointErrors.shelf()

    def errors(miss_factor: float = 1.0, swap_rate: float | None = None) -> KeypointErrors:
        return KeypointErrors(
            miss_rate=np.minimum(1.0, miss_factor * np.asarray(shelf_errors.miss_rate)),
            hidden_miss_rate=np.minimum(
                1.0, miss_factor * np.asarray(shelf_errors.hidden_miss_rate)
            ),
            swap_rate=shelf_errors.swap_rate if swap_rate is None else swap_rate,
        )

    fitted = dict(sigma=sigma, nu=nu, view_spread=0.22, errors=shelf_errors)
    return {
        "fitted": fitted,
        "σ × 0.5": {**fitted, "sigma": 0.5 * sigma},
        "σ × 1.5": {**fitted, "sigma": 1.5 * sigma},
        "misses × 2": {**fitted, "errors": errors(miss_factor=2.0)},
        "swaps 2 %": {**fitted, "errors": errors(swap_rate=0.02)},
        "clutter 5 / view": {**fitted, "realism": {"clutter_rate": 5.0}},
        "doubles 5 %": {**fitted, "realism": {"double_rate": 0.05, "double_offset_px": 6.0}},
        "cameras off 0.2°": {**fitted, "realism": {"rotation_deg": 0.2}},
        "6–8 people": {**fitted, "people": (6, 8)},
    }


def shelf_rig(data: str):
    """Shelf's cameras with the world moved by :data:`SHELF_CENTRE` (a generator point ``X``
    is Shelf's ``X + SHELF_CENTRE``), and the image size."""
    from cdog_jax import rig_from_arrays

    _, K, R, t, size = shelf["read_calibration"](os.path.join(data, "calibration.json"))
    t = t + np.einsum("mij,j->mi", R, SHELF_CENTRE)
    return rig_from_arrays(K.astype(np.float32), R.astype(np.float32), t.astype(np.float32)), size


def synthetic_scenes(
    rig,
    size,
    *,
    sigma,
    view_spread,
    errors,
    sequences,
    frames,
    tail_share=0.0,
    tail_scale=10.0,
    nu=math.inf,
    seed=0,
    people=(3, 5),
    realism=None,
):
    """``(xy, mask, classes, joints3d, exists, instances)`` stacked over sequences:
    ``(F, M, S, 2)``, ``(F, M, S)``, ``(F, M, S)``, ``(F, K, 17, 3)``, ``(F, K)`` and the
    per-view instance of every detection ``(F, M, S)`` (its person, numbered in each view and
    frame in a random order, as a 2D pose detector numbers them; -1 for none).

    ``errors``: :meth:`KeypointErrors.shelf` (True), none (False) or a
    :class:`KeypointErrors`; ``people``: the fewest and most people of a sequence;
    ``realism``: more :class:`Realism` fields (clutter, doubles, calibration error)."""
    import jax

    from cdog_jax.synthetic import KeypointErrors, Realism, generate_skeleton_scenes

    if isinstance(errors, bool):
        errors = KeypointErrors.shelf() if errors else KeypointErrors()
    realism = dict(realism or {})
    # A view's slots beyond its people's joints: a quarter of them for doubles (at the
    # study's 5 % a view overflows them about never) and the clutter's mean + 4 SD + 2.
    clutter = realism.get("clutter_rate", 0.0)
    clutter_capacity = 0 if not clutter else int(math.ceil(clutter + 4 * math.sqrt(clutter) + 2))
    double_capacity = 0 if not realism.get("double_rate", 0.0) else 17 * people[1] // 4
    rng = np.random.default_rng(seed)
    parts = []
    for s in range(sequences):
        scenes = generate_skeleton_scenes(
            jax.random.PRNGKey(seed * 1000 + s),
            rig,
            int(rng.integers(people[0], people[1] + 1)),
            sigma,
            realism=Realism(
                nu=nu,
                view_spread=view_spread,
                far_share=tail_share,
                far_scale=tail_scale,
                **realism,
            ),
            keypoint_errors=errors,
            num_frames=frames,
            max_people=people[1],
            fps=25.0,
            image_size=tuple(size),
            double_capacity=double_capacity,
            clutter_capacity=clutter_capacity,
        )
        f = scenes.frames
        person = np.asarray(scenes.person)
        K = scenes.exists.shape[0]
        order = np.argsort(rng.random(person.shape[:2] + (K,)), axis=-1)  # (F, M, K)
        instances = np.where(
            person >= 0, np.take_along_axis(order, np.maximum(person, 0), axis=-1), -1
        )
        parts.append(
            (
                np.asarray(f.xy),
                np.asarray(f.mask),
                np.asarray(f.class_id),
                np.asarray(scenes.joints3d),
                np.broadcast_to(np.asarray(scenes.exists), (frames, K)),
                instances,
            )
        )
    return tuple(np.concatenate(a) for a in zip(*parts))


def seen_by_every_camera(rig, size, joints3d: np.ndarray) -> np.ndarray:
    """``(F, K)``: each synthetic person seen by every camera of ``rig`` (at least
    ``shelf_detections.SEEN_SHARE`` of its limb joints in the camera's image), as Shelf's
    annotated actors are in 245 of 246 dev (actor, frame)."""
    K, R, t = (np.asarray(a, np.float64) for a in (rig.K, rig.R, rig.t))
    seen = shelf_detections["cameras_seeing"](K, R, t, size, joints3d[..., LIMBS, :])
    return seen == len(K)


def synthetic_recall(assoc, joints3d, exists) -> float:
    """Share of (frame, existing person, limb joint) with a valid 3D point of that joint type
    within :data:`RECALL_RADIUS_M`."""
    a = assoc.association
    points, valid = np.asarray(a.points3d), np.asarray(a.valid)
    cls = np.asarray(assoc.group_class)
    hit = total = 0
    for f in range(joints3d.shape[0]):
        for j in LIMBS:
            found = points[f][valid[f] & (cls[f] == j)]
            for k in np.flatnonzero(exists[f]):
                total += 1
                if len(found) and np.min(np.linalg.norm(found - joints3d[f, k, j], axis=1)) <= (
                    RECALL_RADIUS_M
                ):
                    hit += 1
    return hit / max(total, 1)


def run_synthetic(rig, scenes, method) -> tuple[float, float]:
    """Recall of ``method`` (a preset's name or a :class:`cdog_jax.Config`) on ``scenes``
    joint by joint, and its wall time (s)."""
    import cdog_jax

    xy, mask, classes, joints3d, exists, _ = scenes
    start = time.perf_counter()
    out = cdog_jax.associate_classes(
        rig, xy, mask, classes, num_classes=17, method=method, sigma_pool="scene"
    )
    return synthetic_recall(out, joints3d, exists), time.perf_counter() - start


# BODY_25 index of every COCO-17 joint; BODY_25's neck and mid-hip are made from the
# shoulders and the hips, as Shelf's PCP reads them (shelf_score.shelf_from_body25).
BODY25_OF_COCO = (0, 16, 15, 18, 17, 5, 2, 6, 3, 7, 4, 12, 9, 13, 10, 14, 11)


def shelf_joints(coco: np.ndarray) -> np.ndarray:
    """Shelf's ``(15, 3)`` joints from COCO-17 joints ``(17, 3)`` (NaN: missing)."""
    body = np.full((25, 3), np.nan)
    body[list(BODY25_OF_COCO)] = coco
    body[1] = 0.5 * (coco[5] + coco[6])  # neck: the shoulders' centre
    body[8] = 0.5 * (coco[11] + coco[12])  # mid-hip
    return shelf_score["shelf_from_body25"](body)


def synthetic_pcp(rig, scenes, preset: str) -> dict:
    """Shelf's PCP (10 parts, actors 0–2) of the people of ``preset`` with the person vote:
    ``associate_classes(..., instances=, person_vote=True)``, then ``identify_people``; the
    scores of :mod:`shelf_score` (``pcp_mean``, ``pcp_parts``, ...)."""
    import cdog_jax

    xy, mask, classes, joints3d, exists, instances = scenes
    result = cdog_jax.associate_classes(
        rig,
        xy,
        mask,
        classes,
        num_classes=17,
        method=preset,
        instances=instances,
        person_vote=True,
    )
    people = cdog_jax.identify_people(result, instances)
    predicted = [
        [shelf_joints(people.points[f, n]) for n in np.flatnonzero(people.person_id[f] >= 0)]
        for f in range(xy.shape[0])
    ]
    truth = [
        {int(k): shelf_joints(joints3d[f, k]) for k in np.flatnonzero(exists[f])}
        for f in range(xy.shape[0])
    ]
    return shelf_score["pcp"](predicted, truth, range(xy.shape[0]))


def real_rows(data: str, work: str) -> dict[str, float]:
    per_joint = runpy.run_path(os.path.join(HERE, "shelf_per_joint.py"), run_name="per_joint")
    rows = per_joint["main"]([data, "--work", work, "--rows", ",".join(f"{p}()" for p in PRESETS)])
    return {r["row"].rstrip("()"): r["recall_10cm"] for r in rows}


def left_out_rows(data, work, rig, scenes, rows, table) -> list[dict]:
    """Each ``LEFT_OUT`` row's recall on Shelf and on ``scenes`` (the ``+ keypoint errors``
    scenes), and what the stage is worth on each: its preset's recall (from ``table``) less
    the row's."""
    import cdog_jax

    methods = {row: getattr(cdog_jax.Config, LEFT_OUT[row][0])(**LEFT_OUT[row][1]) for row in rows}
    per_joint = runpy.run_path(os.path.join(HERE, "shelf_per_joint.py"), run_name="per_joint")
    found = per_joint["recall_rows"](data, work, {row: (m, {}) for row, m in methods.items()})
    real = {row: recall for row, (recall, _) in found.items()}
    out = []
    for row, method in methods.items():
        preset = LEFT_OUT[row][0]
        synthetic, _ = run_synthetic(rig, scenes, method)
        base_real = table[preset]["shelf dev frames"]
        base_synthetic = table[preset]["+ keypoint errors"]
        out.append(
            {
                "row": row,
                "shelf": real[row],
                "synthetic": synthetic,
                "worth_on_shelf": None if base_real is None else base_real - real[row],
                "worth_on_synthetic": base_synthetic - synthetic,
            }
        )
        print(f"{row:28s} Shelf {real[row]:.3f} synthetic {synthetic:.3f}", flush=True)
    return out


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("data", help="a local copy of the 4D-association repository's data/shelf")
    p.add_argument(
        "--work", default=os.path.join(os.path.expanduser("~"), ".cache", "cdog_jax", "shelf")
    )
    p.add_argument("--real-json", help="the real rows as shelf_per_joint.py --out wrote them")
    p.add_argument("--sigma", type=float, default=5.0, help="px (default 5)")
    p.add_argument("--sequences", type=int, default=16)
    p.add_argument("--frames", type=int, default=10)
    p.add_argument("--presets", default=",".join(PRESETS))
    p.add_argument(
        "--tail-share", type=float, default=0.02, help="share of far-off detections (default 0.02)"
    )
    p.add_argument(
        "--tail-scale", type=float, default=10.0, help="their noise multiplier (default 10)"
    )
    p.add_argument(
        "--real-pcp",
        type=float,
        help="Shelf's dev PCP of best() with the person vote and no temporal prior "
        "(shelf_table.py's --no-temporal-prior row), for the PCP line",
    )
    p.add_argument(
        "--nu",
        type=float,
        default=math.inf,
        help="Student-t degrees of freedom of every setting's noise, its bulk's spread kept "
        "(Realism.nu; default inf: Gaussian)",
    )
    p.add_argument(
        "--scored",
        choices=("all", "seen-by-every-camera"),
        default="all",
        help="the synthetic people that recall and PCP count: all (default), or those seen by "
        "every camera, as Shelf annotates its actors",
    )
    p.add_argument("--pcp-preset", default="best", help="the preset of the PCP line")
    p.add_argument(
        "--left-out",
        help="also these rows, comma-separated, or 'all': " + "; ".join(LEFT_OUT),
    )
    p.add_argument(
        "--robustness",
        action="store_true",
        help="the robustness study instead of the check: the fitted generator (--sigma, --nu, "
        "the views' spread, the detector's errors) and one thing at a time made harder: "
        + "; ".join(robustness_settings(5.0, math.inf))
        + " (σ relative to --sigma)",
    )
    p.add_argument("--json", help="write the table here")
    args = p.parse_args(argv)
    if args.robustness and args.left_out:
        p.error("--left-out reads the check's '+ keypoint errors' scenes: not with --robustness")
    presets = [s.strip() for s in args.presets.split(",")]
    left_out = []
    if args.left_out:
        left_out = (
            list(LEFT_OUT)
            if args.left_out == "all"
            else [s.strip() for s in args.left_out.split(",")]
        )
        for row in left_out:
            if row not in LEFT_OUT:
                p.error(f"--left-out: no row named {row!r}; the rows: {'; '.join(LEFT_OUT)}")
            if LEFT_OUT[row][0] not in presets:
                p.error(f"--left-out {row!r} needs {LEFT_OUT[row][0]!r} in --presets")
    if args.real_json:
        with open(args.real_json) as f:
            real = {r["row"].rstrip("()"): r["recall_10cm"] for r in json.load(f)}
    else:
        real = real_rows(args.data, args.work)
    rig, size = shelf_rig(args.data)
    noise = dict(sigma=args.sigma, nu=args.nu)
    settings = (
        robustness_settings(args.sigma, args.nu)
        if args.robustness
        else {
            "clean": dict(**noise, view_spread=0.0, errors=False),
            "+ view spread": dict(**noise, view_spread=0.22, errors=False),
            "+ keypoint errors": dict(**noise, view_spread=0.22, errors=True),
            "+ error tails": dict(
                **noise,
                view_spread=0.22,
                errors=True,
                tail_share=args.tail_share,
                tail_scale=args.tail_scale,
            ),
        }
    )
    table = {name: {"shelf dev frames": real.get(name)} for name in presets}
    table["pcp"] = {"shelf dev frames": args.real_pcp}
    table["pcp_parts"] = {}
    for setting, options in settings.items():
        scenes = synthetic_scenes(
            rig, size, sequences=args.sequences, frames=args.frames, **options
        )
        if args.scored == "seen-by-every-camera":  # the others are left out of the scores
            xy, mask, classes, joints3d, exists, instances = scenes
            exists = exists & seen_by_every_camera(rig, size, joints3d)
            scenes = (xy, mask, classes, joints3d, exists, instances)
        for name in presets:
            recall, seconds = run_synthetic(rig, scenes, name)
            table[name][setting] = recall
            print(f"{setting:18s} {name:10s} recall {recall:.3f} ({seconds:.0f} s)", flush=True)
        score = synthetic_pcp(rig, scenes, args.pcp_preset)
        table["pcp"][setting], table["pcp_parts"][setting] = score["pcp_mean"], score["pcp_parts"]
        print(f"{setting:18s} {args.pcp_preset}() people, PCP {table['pcp'][setting]}", flush=True)
        if setting == "+ keypoint errors" and left_out:
            table["left_out"] = left_out_rows(args.data, args.work, rig, scenes, left_out, table)
    print("| preset | Shelf dev frames | " + " | ".join(settings) + " |")
    print("|---|---|" + "---|" * len(settings))
    for name in presets:
        row = table[name]
        cells = [f"{row[s]:.3f}" for s in settings]
        shown = "" if row["shelf dev frames"] is None else f"{row['shelf dev frames']:.3f}"
        print(f"| {name}() | {shown} | " + " | ".join(cells) + " |")
    row = table["pcp"]
    real_pcp = "" if row["shelf dev frames"] is None else f"{row['shelf dev frames']:.1f}"
    print(
        f"| PCP, {args.pcp_preset}() + person vote | {real_pcp} | "
        + " | ".join(f"{row[s]:.1f}" for s in settings)
        + " |"
    )
    if left_out:
        print("\n| left out | Shelf dev frames | + keypoint errors | worth on Shelf / synthetic |")
        print("|---|---|---|---|")
        for r in table["left_out"]:
            worth = "" if r["worth_on_shelf"] is None else f"{r['worth_on_shelf']:+.3f}"
            print(
                f"| {r['row']} | {r['shelf']:.3f} | {r['synthetic']:.3f} | "
                f"{worth} / {r['worth_on_synthetic']:+.3f} |"
            )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(table, f, indent=1)
    return table


if __name__ == "__main__":
    main()
