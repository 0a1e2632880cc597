"""Speed of the benchmark sweep and of one scene.

Questions:

1. How long does the full docs/BENCHMARK.md §1 grid (21 σ × 42 counts × 5 scenes = 4,410 scenes,
   10 views, generate + associate + score) take in one ``sweep`` call, cold (a fresh
   process: trace + compile + run) and warm (the same call again), and how much memory?
2. How does the time of one scene grow with its point count (warm; compile apart)?

Each full-grid run is a fresh Python process (so "cold" really compiles from nothing; no
persistent compilation cache) that calls ``sweep(default_rig(), Grid.paper(), methods=…,
timing=False)`` once cold and ``--warm`` times warm. Reported: medians over ``--runs``
processes of the cold call (wall, of which compile), the warm call, the throughput, and
the process's peak RSS (``ru_maxrss``; device memory too on a GPU).
Single scenes: ``associate`` on one scene of each count at σ = 1, capacity = count, the
median of ``--single-runs`` warm calls.

The grid runs once with one JAX CPU device and once with one device per core
(``--cpu-devices``; ``cdog_jax.benchmark.use_cpu_cores``): :func:`sweep` shards its scenes
over the devices, so on a CPU the second uses every core. Both columns are printed beside
the numbers measured before the sweep used more than one core.

Usage: ``python experiments/bench_speed.py [--runs 3] [--methods paper,reference] [--quick]
[--cpu-devices 1,0] [--skip-grid] [--skip-single]``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time

import numpy as np

SINGLE_COUNTS = (5, 10, 20, 40, 70, 100, 130)


def _child(methods: list[str], quick: bool, warm_runs: int, cpu_devices: int) -> dict:
    """One process: the cold call, then ``warm_runs`` warm calls; returns the timings.
    ``cpu_devices``: JAX CPU devices (0: one per core), chosen before JAX runs anything."""
    t_start = time.perf_counter()
    import jax

    from cdog_jax.benchmark import METHODS, Grid, sweep, use_cpu_cores

    use_cpu_cores(count=cpu_devices or None)
    from cdog_jax.synthetic import default_rig

    grid = Grid.quick() if quick else Grid.paper()
    configs = {name: METHODS[name]() for name in methods}
    rig = default_rig()
    t0 = time.perf_counter()
    cold = sweep(rig, grid, methods=configs, timing=False)
    cold_s = time.perf_counter() - t0
    warm = []
    for _ in range(warm_runs):
        t0 = time.perf_counter()
        sweep(rig, grid, methods=configs, timing=False)
        warm.append(time.perf_counter() - t0)
    out = {
        "scenes": grid.num_scenes,
        "cold_s": cold_s,
        "compile_s": cold.compile_s,
        "warm_s": float(np.median(warm)),
        "process_s": time.perf_counter() - t_start,
        "rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6,  # KiB on Linux
        "device": cold.device,
        "devices": jax.device_count(),
        "pg_f1": {name: float(np.mean(cold.metrics[name]["pg_f1"])) for name in configs},
    }
    stats = jax.devices()[0].memory_stats() if jax.default_backend() != "cpu" else None
    if stats:
        out["device_peak_gb"] = stats.get("peak_bytes_in_use", 0) / 1e9
    return out


def full_grid(
    methods: list[str], runs: int, quick: bool, warm_runs: int, cpu_devices: int
) -> list[dict]:
    """``runs`` fresh processes of :func:`_child`; their JSON reports."""
    reports = []
    for r in range(runs):
        cmd = [
            sys.executable,
            __file__,
            "--_child",
            "--methods",
            ",".join(methods),
            "--warm",
            str(warm_runs),
            "--cpu-devices",
            str(cpu_devices),
        ]
        if quick:
            cmd.append("--quick")
        env = dict(os.environ, CDOG_JAX_CACHE="0")  # every cold call compiles from nothing
        proc = subprocess.run(cmd, capture_output=True, text=True, check=False, env=env)
        if proc.returncode != 0:
            raise RuntimeError(f"run {r} failed:\n{proc.stderr[-3000:]}")
        reports.append(json.loads(proc.stdout.strip().splitlines()[-1]))
        rep = reports[-1]
        print(
            f"  run {r + 1}/{runs}: cold {rep['cold_s']:.1f} s (compile {rep['compile_s']:.1f} s), "
            f"warm {rep['warm_s']:.1f} s, peak RSS {rep['rss_gb']:.2f} GB",
            flush=True,
        )
    return reports


def single_scene(methods: list[str], counts=SINGLE_COUNTS, runs: int = 7) -> list[tuple]:
    """``(method, count, compile_s, warm_s)`` for one scene of each count."""
    import jax

    import cdog_jax
    from cdog_jax.benchmark import METHODS
    from cdog_jax.synthetic import default_rig, generate_scene

    rig = default_rig()
    rows = []
    for name in methods:
        config = METHODS[name]()
        for n in counts:
            scene = generate_scene(jax.random.PRNGKey(n), rig, n, 1.0, capacity=n)

            def call():
                return jax.block_until_ready(
                    cdog_jax.associate(rig, scene.xy, scene.mask, method=config, sigma=1.0)
                )

            t0 = time.perf_counter()
            call()
            first = time.perf_counter() - t0
            times = []
            for _ in range(runs):
                t0 = time.perf_counter()
                call()
                times.append(time.perf_counter() - t0)
            warm = float(np.median(times))
            rows.append((name, n, first - warm, warm))
    return rows


#: The full grid with paper() on the 2-core CPU before the sweep used more than one core
#: (one device, median of 3 fresh processes): cold call, compile, warm call (s).
REFERENCE_2CORE = {"cold_s": 37.0, "compile_s": 19.0, "warm_s": 17.9}


def _grid_table(columns: list[list[dict]]) -> None:
    """One column per device count (medians over its processes), then the reference."""
    meds = [
        {
            k: float(np.median([r[k] for r in reps]))
            for k in ("cold_s", "compile_s", "warm_s", "rss_gb", "process_s")
        }
        for reps in columns
    ]
    scenes = columns[0][0]["scenes"]
    head = " | ".join(f"{reps[0]['device']}, median of {len(reps)}" for reps in columns)
    print(f"\n| grid ({scenes} scenes) | {head} | before (1 device, 2-core CPU) |")
    print("|---" * (len(columns) + 2) + "|")

    def row(label, fmt, key, ref=None):
        cells = " | ".join(fmt(m[key]) for m in meds)
        print(f"| {label} | {cells} | {fmt(ref) if ref is not None else ''} |")

    row(
        "cold call (trace + compile + run)",
        lambda v: f"{v:.1f} s",
        "cold_s",
        REFERENCE_2CORE["cold_s"],
    )
    row("of which compile", lambda v: f"{v:.1f} s", "compile_s", REFERENCE_2CORE["compile_s"])
    row("warm call", lambda v: f"{v:.1f} s", "warm_s", REFERENCE_2CORE["warm_s"])
    row(
        "throughput, warm",
        lambda v: f"{scenes / v:.0f} scenes/s",
        "warm_s",
        REFERENCE_2CORE["warm_s"],
    )
    row("whole process (imports included)", lambda v: f"{v:.1f} s", "process_s")
    row("peak RSS", lambda v: f"{v:.2f} GB", "rss_gb")
    if "device_peak_gb" in columns[0][0]:
        print(
            "| peak device memory | "
            + " | ".join(
                f"{np.median([r['device_peak_gb'] for r in reps]):.2f} GB" for reps in columns
            )
            + " | |"
        )
    print(
        "| mean PG-F1 over the grid | "
        + " | ".join(
            ", ".join(f"{k} {v:.4f}" for k, v in reps[0]["pg_f1"].items()) for reps in columns
        )
        + " | |"
    )


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--runs", type=int, default=3, help="fresh processes for the full grid (default 3)"
    )
    parser.add_argument("--warm", type=int, default=3, help="warm calls per process (median kept)")
    parser.add_argument("--single-runs", type=int, default=7)
    parser.add_argument(
        "--single-counts",
        type=int,
        nargs="+",
        default=SINGLE_COUNTS,
        help="points per single scene",
    )
    parser.add_argument(
        "--methods", default="paper", help="comma list of cdog-jax benchmark methods"
    )
    parser.add_argument(
        "--quick", action="store_true", help="the --quick grid instead of the full one"
    )
    parser.add_argument("--skip-grid", action="store_true")
    parser.add_argument("--skip-single", action="store_true")
    parser.add_argument(
        "--cpu-devices",
        default="1,0",
        help="comma list of JAX CPU device counts to run the grid with, side by side (0: one per core; "
        "default 1,0: one core, then every core)",
    )
    parser.add_argument("--_child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    if args._child:
        print(json.dumps(_child(methods, args.quick, args.warm, int(args.cpu_devices))))
        return

    import jax

    print(
        f"JAX {jax.__version__} on {jax.default_backend()} ({jax.device_count()} device(s)); methods {methods}"
    )
    if not args.skip_grid:
        columns = []
        for count in (int(c) for c in args.cpu_devices.split(",")):
            print(
                f"Full grid, {args.runs} fresh processes, {count or 'one per core'} CPU device(s):",
                flush=True,
            )
            columns.append(full_grid(methods, args.runs, args.quick, args.warm, count))
        _grid_table(columns)
    if not args.skip_single:
        print(
            f"\nSingle scene, σ = 1 px, capacity = count, median of {args.single_runs} warm calls:"
        )
        print("| method | points | compile (s) | warm (ms) |\n|---|---|---|---|")
        for name, n, compile_s, warm_s in single_scene(
            methods, tuple(args.single_counts), runs=args.single_runs
        ):
            print(f"| {name} | {n} | {compile_s:.2f} | {1000 * warm_s:.1f} |")


if __name__ == "__main__":
    main()
