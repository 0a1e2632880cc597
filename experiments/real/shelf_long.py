"""A long recording through the command line: wall time, frames per second and peak memory of
``cdog-jax associate`` on Shelf's OpenPose frames and on the same frames repeated.

The question: does the command's memory stay the same whatever the recording's length, and
how fast is it per frame? Shelf's 301 frames (prepared as :mod:`shelf` does: its rig JSON and
one OpenPose folder per camera) are linked ``--repeat`` times over into one longer recording
(frame ``k + 301 r`` of a view is a link to frame ``k``), so that the long run reads the same
detections in the same way; nothing is scored. Each length runs ``--runs`` times as a whole
process after one warm-up (the compilation cache filled); the script prints the median wall
time, the largest peak resident memory (the child's ``ru_maxrss``) and each run's peak: a
long recording goes through the command in parts, and its peak is the largest of its parts'
peaks, each of which varies from run to run as a short recording's does.

    python experiments/real/shelf_long.py PATH/TO/data/shelf                # 301 and 3,010
    python experiments/real/shelf_long.py PATH/TO/data/shelf --repeat 20 -- --no-temporal-prior

Options after ``--`` go to the command. The Shelf copy's origin: see :mod:`shelf`.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from shelf import prepare  # noqa: E402


def repeated(pose: str, folder: str, frames: int, repeat: int) -> str:
    """``folder/pose``: every view of ``pose`` (``<frame>_keypoints.json`` files) linked
    ``repeat`` times over, frame ``k + frames · r`` the link to frame ``k``."""
    out = os.path.join(folder, "pose")
    for view in sorted(os.listdir(pose)):
        os.makedirs(os.path.join(out, view), exist_ok=True)
        for r in range(repeat):
            for k in range(frames):
                os.symlink(
                    os.path.abspath(os.path.join(pose, view, f"{k:06d}_keypoints.json")),
                    os.path.join(out, view, f"{k + frames * r:06d}_keypoints.json"),
                )
    return out


def run(rig: str, pose: str, out: str, extra: list[str]) -> tuple[float, float]:
    """One whole ``cdog-jax associate`` process: its wall time (s) and peak resident memory
    (MiB). The peak is read from a child of its own so that no earlier run's counts."""
    probe = (
        "import resource, subprocess, sys, time; t = time.perf_counter(); "
        "done = subprocess.run(sys.argv[1:], capture_output=True, text=True); "
        "w = time.perf_counter() - t; "
        "sys.stderr.write(done.stderr) if done.returncode else None; "
        "print(w, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss); "
        "sys.exit(done.returncode)"
    )
    if os.path.exists(out):
        os.remove(out)
    cmd = [sys.executable, "-m", "cdog_jax", "associate", "--rig", rig, "--points", pose]
    cmd += ["--keypoints", "BODY_25", "--out", out, *extra]
    done = subprocess.run([sys.executable, "-c", probe, *cmd], capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"cdog-jax associate failed ({done.returncode}): {done.stderr.strip()}")
    wall, kib = done.stdout.split()
    return float(wall), int(kib) / 1024


def main(argv: list[str] | None = None) -> dict:
    argv = sys.argv[1:] if argv is None else argv
    extra = argv[argv.index("--") + 1 :] if "--" in argv else []
    argv = argv[: argv.index("--")] if "--" in argv else argv
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("data", help="the data/shelf folder of the 4D-association repository")
    parser.add_argument("--repeat", type=int, default=10, help="the long recording: N × 301")
    parser.add_argument("--runs", type=int, default=3, help="timed runs of each length")
    parser.add_argument("--work", default=None, help="folder for the prepared files")
    parser.add_argument("--json", default=None, help="also write the numbers to this JSON file")
    args = parser.parse_args(argv)
    if args.repeat < 1 or args.runs < 1:
        parser.error("--repeat and --runs must be at least 1")
    work = args.work or tempfile.mkdtemp(prefix="shelf_long_")
    prepared = prepare(args.data, work)
    frames = prepared["frames"]
    long_folder = os.path.join(work, f"x{args.repeat}")
    long_pose = os.path.join(long_folder, "pose")
    if not os.path.isdir(long_pose):
        repeated(prepared["pose"], long_folder, frames, args.repeat)
    rows = []
    for count, pose in ((frames, prepared["pose"]), (frames * args.repeat, long_pose)):
        out = os.path.join(work, f"result_{count}.npz")
        run(prepared["rig"], pose, out, extra)  # warm-up: the compilation cache filled
        walls, peaks = [], []
        for _ in range(args.runs):
            wall, peak = run(prepared["rig"], pose, out, extra)
            walls.append(wall)
            peaks.append(peak)
        wall = sorted(walls)[len(walls) // 2]
        rows.append(
            {
                "frames": count,
                "wall_s": round(wall, 2),
                "frames_per_s": round(count / wall, 1),
                "peak_mib": round(max(peaks)),
                "walls_s": [round(w, 2) for w in walls],
                "peaks_mib": [round(p) for p in peaks],
            }
        )
    print(f"cdog-jax associate {' '.join(extra) or '(defaults)'}, {args.runs} runs each:")
    print("| frames | wall (median) | frames/s | peak memory (largest) | each run's peak |")
    print("|---|---|---|---|---|")
    for row in rows:
        print(
            f"| {row['frames']:,} | {row['wall_s']:.1f} s | {row['frames_per_s']:.0f} "
            f"| {row['peak_mib']:,} MiB | {', '.join(f'{p:,}' for p in row['peaks_mib'])} MiB |"
        )
    result = {"options": " ".join(extra), "rows": rows, "machine_cpus": os.cpu_count()}
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=1)
    return result


if __name__ == "__main__":
    t0 = time.perf_counter()
    main()
    print(
        f"({time.perf_counter() - t0:.0f} s in all; peak memory of this script itself "
        f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024} MiB)"
    )
