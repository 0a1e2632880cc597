"""A frame loop as a live user runs it: one frame per call, warm, in one process.

Questions:

1. Shelf-like frames (5 cameras, 25 keypoint classes, 2–4 people, about one detection in
   ten missed, a few stray detections per view; ~250–400 detections a frame) through
   :func:`cdog_jax.associate_classes` with its defaults (σ estimated per frame): the time
   per frame (p50 / p95 / p99), the first call (compile), and whether memory maps and
   resident memory stay flat over ``--frames`` frames.
2. The same frames through one :class:`cdog_jax.LiveAssociator` (25 classes; its defaults:
   tracks and the temporal prior; with σ fitted on the first frame and held; without the
   prior): the first frame and the warm time per frame.
3. One 10-camera frame of 130 points through :func:`cdog_jax.associate` with its defaults:
   the warm time per frame.

Frames are drawn once (``--pool`` distinct frames, cycled), so that frames of different
counts meet the same programs as in a recording. Targets beside the numbers: p50 ≤ 6 ms and
p99 ≤ 20 ms per Shelf-like frame, 10 × 130 ≤ 50 ms; the original C-DOG code needs 0.35–2.6 s
per frame, 4D association runs at 30 frames/s with 5 cameras.

    python experiments/bench_live.py                 # 2,000 frames
    python experiments/bench_live.py --frames 300 --out live.json
    python experiments/bench_live.py --skip-prior --skip-ten-views   # memory over 2,000 frames
    python experiments/bench_live.py --parts --frames 200   # inside and outside compiled code
    python experiments/bench_live.py --shelf PATH/data/shelf --frames 600   # real frames
    python experiments/bench_live.py --shelf PATH/data/shelf --cores 2   # one device a core
"""

from __future__ import annotations

import argparse
import json
import resource
import time

import jax
import jax.numpy as jnp
import numpy as np

import cdog_jax
from cdog_jax.synthetic import DEFAULT_BOX, default_rig, generate_scene

TARGETS_MS = {"shelf_p50": 6.0, "shelf_p99": 20.0, "ten_views_130_points": 50.0}
TARGET_FRAMES_PER_S = 154  # the cross-view tracker of Chen et al. with 12 cameras


def shelf_like_frames(rig, count: int, classes: int = 25, seed: int = 0):
    """``count`` frames, each ``(xy (1, M, P, 2), mask, classes, instances)`` with its own
    ``P``: 2–4 people whose joints lie within 15 % of the box of a centre, σ = 2 px, 10 % of the
    detections missed, 0–2 stray detections of random class per view."""
    rng = np.random.default_rng(seed)
    lo, hi = (np.asarray(b) for b in DEFAULT_BOX)
    spread = 0.15 * (hi - lo)  # a person's joints lie within this of its centre, per axis
    M = rig.num_views
    frames = []
    for _ in range(count):
        people = int(rng.integers(2, 5))
        centres = rng.uniform(lo + spread, hi - spread, (people, 1, 3))
        X = (centres + rng.uniform(-spread, spread, (people, classes, 3))).reshape(-1, 3)
        xy, _ = cdog_jax.project(rig, jnp.asarray(X, jnp.float32))
        xy = np.asarray(xy) + rng.normal(0.0, 2.0, (M, len(X), 2))
        cls = np.broadcast_to(np.tile(np.arange(classes), people), (M, len(X))).copy()
        inst = np.broadcast_to(np.repeat(np.arange(people), classes), (M, len(X))).copy()
        keep = rng.random((M, len(X))) > 0.1
        strays = rng.integers(0, 3, M)
        P = int((keep.sum(1) + strays).max())
        f_xy, f_mask = np.zeros((M, P, 2), np.float32), np.zeros((M, P), bool)
        f_cls, f_inst = np.zeros((M, P), np.int64), np.full((M, P), -1, np.int64)
        for m in range(M):
            n = int(keep[m].sum())
            order = rng.permutation(n + strays[m])
            x = np.concatenate([xy[m, keep[m]], rng.uniform((0, 0), (640, 480), (strays[m], 2))])
            c = np.concatenate([cls[m, keep[m]], rng.integers(0, classes, strays[m])])
            i = np.concatenate([inst[m, keep[m]], np.full(strays[m], -1)])
            f_xy[m, : len(order)], f_cls[m, : len(order)], f_inst[m, : len(order)] = (
                x[order],
                c[order],
                i[order],
            )
            f_mask[m, : len(order)] = True
        frames.append((f_xy[None], f_mask[None], f_cls[None], f_inst[None]))
    return frames


def _maps() -> int:
    with open("/proc/self/maps", "rb") as f:
        return sum(1 for _ in f)


def _rss_gb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * resource.getpagesize() / 1e9


def _percentiles(seconds) -> dict:
    """p50 / p95 / p99 (ms) of per-frame ``seconds``, and the frames per second they make."""
    ms = 1e3 * np.asarray(seconds)
    rate = {"frames_per_s": float(1e3 / ms.mean())} if ms.size else {}
    return {**{f"p{q}_ms": float(np.percentile(ms, q)) for q in (50, 95, 99)}, **rate}


def shelf_loop(frames, rig, count: int, checkpoints: int = 5) -> dict:
    """``count`` calls over the cycled ``frames``: first-call time, warm percentiles and the
    memory maps and resident memory at a few points of the loop."""
    t0 = time.perf_counter()
    for xy, mask, cls, _ in frames:  # every frame once: compiles whatever its shapes need
        cdog_jax.associate_classes(rig, xy, mask, cls)
    warm_up_s = time.perf_counter() - t0
    memory, times = [], []
    marks = set(np.linspace(0, count - 1, checkpoints).astype(int).tolist())
    for i in range(count):
        xy, mask, cls, _ = frames[i % len(frames)]
        t = time.perf_counter()
        cdog_jax.associate_classes(rig, xy, mask, cls)
        times.append(time.perf_counter() - t)
        if i in marks:
            memory.append({"frame": i, "maps": _maps(), "rss_gb": round(_rss_gb(), 3)})
    return {"frames": count, "warm_up_s": warm_up_s, **_percentiles(times), "memory": memory}


def _update(live, frame, instances: bool):
    xy, mask, cls, inst = frame
    return live.update(xy[0], mask[0], classes=cls[0], instances=inst[0] if instances else None)


def live_loop(frames, rig, count: int, instances: bool = False, **options) -> dict:
    """``count`` frames through one :class:`cdog_jax.LiveAssociator` (25 classes; with each
    frame's ``instances``, the person vote and person ids): the first frame (compile), warm
    percentiles, the capacity raises and the memory at the end."""
    live = cdog_jax.LiveAssociator(rig, num_classes=25, **options)
    t = time.perf_counter()
    _update(live, frames[0], instances)
    first = time.perf_counter() - t
    times = []
    for i in range(1, count):
        frame = frames[i % len(frames)]
        t = time.perf_counter()
        _update(live, frame, instances)
        times.append(time.perf_counter() - t)
    return {
        "first_s": first,
        **_percentiles(times),
        "raises": live.compiles,
        "maps": _maps(),
        "rss_gb": round(_rss_gb(), 3),
    }


def live_parts(frames, rig, count: int, instances: bool = False, **options) -> dict:
    """``count`` warm frames through one :class:`cdog_jax.LiveAssociator` (after 40 to warm
    it), each compiled program timed to completion where the frame calls it (the library's
    program calls wrapped for this process only): p50 of each part and of what is left
    outside compiled code (ms)."""
    import cdog_jax._associate as associate_module
    import cdog_jax.people._classes as classes_module
    import cdog_jax.people._persons as persons_module
    import cdog_jax.tracking._live as live_module

    times: dict[str, float] = {}

    def timed(name_of, fun):
        def run(*args, **kwargs):
            t = time.perf_counter()
            out = jax.block_until_ready(fun(*args, **kwargs))
            name = name_of(args)
            times[name] = times.get(name, 0.0) + time.perf_counter() - t
            return out

        return run

    program = lambda args: getattr(args[0], "__name__", str(args[0])).strip("_")  # noqa: E731
    saved = (
        associate_module.call_stored,
        classes_module.call_stored,
        live_module.track_one,
        live_module.track_scenes,
        persons_module._retriangulate,
    )
    associate_module.call_stored = timed(program, saved[0])
    classes_module.call_stored = timed(program, saved[1])
    live_module.track_one = timed(lambda args: "track_one", saved[2])
    live_module.track_scenes = timed(lambda args: "track_scenes", saved[3])
    persons_module._retriangulate = timed(lambda args: "person vote's DLT", saved[4])
    try:
        live = cdog_jax.LiveAssociator(rig, num_classes=25, **options)
        parts: dict[str, list[float]] = {}
        for i in range(40 + count):
            times.clear()
            t = time.perf_counter()
            _update(live, frames[i % len(frames)], instances)
            whole = time.perf_counter() - t
            if i >= 40:
                for name, seconds in times.items():
                    parts.setdefault(name, []).append(seconds)
                parts.setdefault("outside compiled code", []).append(whole - sum(times.values()))
                parts.setdefault("whole update", []).append(whole)
    finally:
        (
            associate_module.call_stored,
            classes_module.call_stored,
            live_module.track_one,
            live_module.track_scenes,
            persons_module._retriangulate,
        ) = saved
    return {name: float(np.median(v)) * 1e3 for name, v in parts.items()}


def _live_line(name: str, t: dict) -> str:
    """One line of :func:`live_loop`'s numbers."""
    return (
        f"{name}: first frame {t['first_s']:.1f} s; per frame p50 {t['p50_ms']:.1f} / "
        f"p95 {t['p95_ms']:.1f} / p99 {t['p99_ms']:.1f} ms (targets {TARGETS_MS['shelf_p50']} / "
        f"{TARGETS_MS['shelf_p99']}), {t['frames_per_s']:.0f} frames/s (target "
        f"{TARGET_FRAMES_PER_S}); {t['raises']} capacity raises; {t['maps']} maps, "
        f"{t['rss_gb']:.2f} GB"
    )


def _parts_line(name: str, parts: dict) -> str:
    """One line of :func:`live_parts`' numbers."""
    return f"{name} (p50 ms): " + ", ".join(f"{k} {v:.2f}" for k, v in parts.items())


def shelf_frames(data: str):
    """Shelf's real frames as a user with OpenPose output has them (``experiments/real/
    shelf.py`` writes the rig and one OpenPose folder per camera from the ``data/shelf``
    folder of github.com/zhangyux15/4d_association; :func:`cdog_jax.io.load_rig` and
    :func:`cdog_jax.io.load_openpose` read them): the rig and the frames as
    :func:`shelf_like_frames` gives them, each with the per-view person of every detection."""
    import os
    import sys
    import tempfile

    from cdog_jax.io import load_openpose, load_rig

    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "real"))
    from shelf import prepare

    paths = prepare(data, tempfile.mkdtemp(prefix="shelf_live_"))
    rig = load_rig(paths["rig"]).rig
    det = load_openpose(paths["pose"], keypoints="BODY_25")
    xy = np.where(det.mask[..., None], det.xy, 0.0).astype(np.float32)
    return rig, [
        (xy[f][None], det.mask[f][None], det.classes[f][None], det.instances[f][None])
        for f in range(det.xy.shape[0])
    ]


def ten_views(count: int = 20) -> dict:
    rig = default_rig(num_views=10)
    scene = generate_scene(jax.random.PRNGKey(0), rig, 130, 1.0, capacity=130)
    xy, mask = np.asarray(scene.xy), np.asarray(scene.mask)
    t = time.perf_counter()
    jax.block_until_ready(cdog_jax.associate(rig, xy, mask))
    first = time.perf_counter() - t
    times = []
    for _ in range(count):
        t = time.perf_counter()
        jax.block_until_ready(cdog_jax.associate(rig, xy, mask))
        times.append(time.perf_counter() - t)
    return {"first_s": first, **_percentiles(times)}


def main(argv=None):
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--frames", type=int, default=2000)
    p.add_argument("--pool", type=int, default=50)
    p.add_argument("--out", help="write the numbers as JSON here")
    p.add_argument("--skip-ten-views", action="store_true")
    p.add_argument(
        "--parts",
        action="store_true",
        help="only the time of each compiled program of a live frame and of the rest (p50)",
    )
    p.add_argument(
        "--skip-prior",
        action="store_true",
        help="leave out the live loop without the temporal prior",
    )
    p.add_argument(
        "--shelf",
        metavar="PATH",
        help="Shelf's real frames (the data/shelf folder of github.com/zhangyux15/4d_association) "
        "through LiveAssociator, with and without each frame's OpenPose people, instead",
    )
    p.add_argument(
        "--cores",
        type=int,
        help="give JAX this many CPU devices first (cdog_jax.benchmark.use_cpu_cores): a live "
        "frame's class scenes then run in one chunk per device, at once",
    )
    args = p.parse_args(argv)
    if args.cores:
        from cdog_jax.benchmark import use_cpu_cores

        print(f"{use_cpu_cores(count=args.cores)} CPU devices")
    if args.shelf:
        return shelf_main(args)
    rig = default_rig(num_views=5)
    frames = shelf_like_frames(rig, args.pool)
    sizes = [int(f[1].sum()) for f in frames]
    print(
        f"Shelf-like frames: 5 views, 25 classes, {min(sizes)}–{max(sizes)} detections, {args.frames} calls"
    )
    if args.parts:
        for name, options in (("σ per frame", {}), ("σ held", {"sigma": "held"})):
            print(
                _parts_line(
                    f"LiveAssociator, {name}", live_parts(frames, rig, args.frames, **options)
                )
            )
        return
    out = {"shelf_like": shelf_loop(frames, rig, args.frames), "targets_ms": TARGETS_MS}
    s = out["shelf_like"]
    print(
        f"  warm-up over {len(frames)} frames {s['warm_up_s']:.1f} s; per frame p50 {s['p50_ms']:.1f} / "
        f"p95 {s['p95_ms']:.1f} / p99 {s['p99_ms']:.1f} ms (targets {TARGETS_MS['shelf_p50']} / {TARGETS_MS['shelf_p99']})"
    )
    for m in s["memory"]:
        print(f"  frame {m['frame']:>5}: {m['maps']} maps, {m['rss_gb']:.2f} GB resident")
    # σ fitted on the first frame and held: what a live loop spares when it does not fit σ
    # on every frame (docs/LIVE.md, "A σ held").
    loops = (("live", {}), ("live_sigma_held", {"sigma": "held"}))
    if not args.skip_prior:
        loops += (("live_without_prior", {"temporal_prior": False}),)
    for name, options in loops:
        out[name] = t = live_loop(frames, rig, args.frames, **options)
        print(_live_line(f"LiveAssociator {options or ''}", t))
    if not args.skip_ten_views:
        out["ten_views_130_points"] = t = ten_views()
        print(
            f"10 views × 130 points: first {t['first_s']:.1f} s, warm p50 {t['p50_ms']:.1f} ms "
            f"(target {TARGETS_MS['ten_views_130_points']})"
        )
    if args.out:
        with open(args.out, "w") as f:
            json.dump(out, f, indent=1)


def shelf_main(args) -> dict:
    """Shelf's 301 real frames, in order (cycled for ``--frames``), through
    :class:`cdog_jax.LiveAssociator` with its defaults: with each frame's OpenPose people
    (the person vote, as a user with OpenPose output runs it) and without; ``--parts``: the
    time of each compiled program and of the rest."""
    rig, frames = shelf_frames(args.shelf)
    sizes = [int(f[1].sum()) for f in frames]
    print(
        f"Shelf: {len(frames)} real frames, 5 views, 25 classes, {min(sizes)}–{max(sizes)} "
        f"detections, {args.frames} calls"
    )
    out = {}
    for name, options in (
        ("with people", {"instances": True}),
        ("without people", {}),
        ("without people, σ held", {"sigma": "held"}),
    ):
        if args.parts:
            print(_parts_line(name, live_parts(frames, rig, args.frames, **options)))
            continue
        out[name] = t = live_loop(frames, rig, args.frames, **options)
        print(_live_line(name, t))
    if args.out:
        with open(args.out, "w") as f:
            json.dump(out, f, indent=1)
    return out


if __name__ == "__main__":
    main()
