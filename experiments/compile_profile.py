"""Where does compiling C-DOG take its time, and how large is the program?

Question: the first call of :func:`cdog_jax.associate` on a new shape waits for XLA to
compile one program of the whole pipeline (seconds on a CPU). Which stages make that
program large and slow to compile, for ``paper()``, ``extended()`` and ``best()`` with σ
given and ``sigma="auto"``?

Method: one synthetic scene (10 views, 30 points in 32 slots, σ = 1 px), the persistent
compilation cache off. Two tables:

1. The whole program (``jax.jit(associate_traced)``): seconds to trace, lower and compile
   (``.trace()``, ``.lower()``, ``.compile()``), warm run time (median of 10), and its size:
   operations of the lowered StableHLO, ``while`` loops in it, and in the optimised HLO
   XLA compiled, the instructions, fusions, distinct kernels and ``while`` loops.
2. Each stage alone: the scene tables (epipolar distances, σ, DLT blocks) as one program,
   then every stage of the config's plan jitted on its own, on the state the stages before
   it produced (so each sees a realistic table): lower + compile seconds and the same
   size counts. A stage listed twice (``refit``, ``seed_again``, ...) is compiled again,
   as it is inlined again in the whole program. The per-stage sum is larger than the whole
   program's compile time (every program has a fixed cost), but it shows the ranking.

Usage: ``python experiments/compile_profile.py [--presets paper,extended,best,former_best]
[--sigma given,auto] [--no-stages]``. Numbers depend on the machine's load: compare runs
made side by side.
"""

from __future__ import annotations

import argparse
import os
import re
import time

os.environ.setdefault("CDOG_JAX_CACHE", "0")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from cdog_jax import Config  # noqa: E402
from cdog_jax._status import Status  # noqa: E402
from cdog_jax.cdog._pipeline import associate_traced, plan, scene_tables  # noqa: E402
from cdog_jax.cdog._stage import GroupTable, State, raise_flag  # noqa: E402
from cdog_jax.synthetic import default_rig, generate_scene  # noqa: E402


def _sizes(lowered, compiled) -> dict:
    """Operations and while loops of the StableHLO; instructions, fusions and while loops
    of the optimised HLO."""
    text = lowered.as_text()
    ops = sum(
        1
        for line in text.splitlines()
        if re.search(r"= (stablehlo|chlo|func|call)\b|stablehlo\.", line)
    )
    hlo = compiled.as_text() or ""
    lines = [line for line in hlo.splitlines() if " = " in line]
    return {
        "ops": ops,
        "while": text.count("stablehlo.while"),
        "hlo": len(lines),
        "fusions": sum(1 for line in lines if " fusion(" in line),
        "kernels": _distinct_kernels(hlo),
        "hlo_while": sum(1 for line in lines if " while(" in line),
    }


def _distinct_kernels(hlo: str) -> int:
    """Fused (and wrapped single-operation) computations of the optimised HLO that differ
    other than by their names: XLA's CPU backend generates code once per distinct kernel
    (``experiments/kernel_cost.py``), so this, not the instruction count, is what compile
    time follows."""
    bodies = set()
    for computation in hlo.split("\n\n"):
        lines = computation.strip().splitlines()
        if not lines or not re.match(r"%?(fused_computation|wrapped_)", lines[0]):
            continue
        body = (
            re.sub(r"%[\w.\-]+", "%", re.sub(r", metadata=\{[^}]*\}", "", line)).strip()
            for line in lines[1:]
        )
        bodies.add("\n".join(body))
    return len(bodies)


def _compile(f, *args):
    """(trace s, lower s, compile s, compiled, sizes and the compile's CPU seconds)."""
    t0 = time.perf_counter()
    traced = jax.jit(f).trace(*args)
    t1 = time.perf_counter()
    lowered = traced.lower()
    t2, c2 = time.perf_counter(), time.process_time()
    compiled = lowered.compile()
    t3, c3 = time.perf_counter(), time.process_time()
    return t1 - t0, t2 - t1, t3 - t2, compiled, dict(_sizes(lowered, compiled), cpu=c3 - c2)


def _scene_inputs(num_points: int = 30, capacity: int = 32, sigma: float = 1.0):
    rig = default_rig()
    scene = generate_scene(jax.random.PRNGKey(0), rig, num_points, sigma, capacity=capacity)
    return rig, jnp.asarray(scene.xy, jnp.float32), jnp.asarray(scene.mask)


def whole_program(config, rig, xy, mask, sigma: float = 1.0) -> dict:
    thresholds = config.thresholds(sigma)
    tr, lo, co, compiled, sizes = _compile(
        lambda r, x, m, t: associate_traced(r, x, m, t, config), rig, xy, mask, thresholds
    )
    jax.block_until_ready(compiled(rig, xy, mask, thresholds))
    warm = []
    for _ in range(10):
        t0 = time.perf_counter()
        jax.block_until_ready(compiled(rig, xy, mask, thresholds))
        warm.append(time.perf_counter() - t0)
    return dict(trace=tr, lower=lo, compile=co, warm_ms=1e3 * float(np.median(warm)), **sizes)


def per_stage(config, rig, xy, mask, sigma: float = 1.0) -> list[tuple[str, dict]]:
    thresholds = config.thresholds(sigma)
    rows = []
    tr, lo, co, compiled, sizes = _compile(
        lambda r, x, m, t: scene_tables(r, x, m, t, config), rig, xy, mask, thresholds
    )
    scene, fallback = compiled(rig, xy, mask, thresholds)
    rows.append(("scene tables", dict(lower=tr + lo, compile=co, **sizes)))
    M, P = mask.shape
    G = max(M * P // 2, 1)
    empty = GroupTable(jnp.full((G, M), -1, jnp.int32), jnp.zeros((G,), bool))
    state = State(empty, None, raise_flag(fallback, Status.SIGMA_FALLBACK))
    for stage, options in plan(config):
        tr, lo, co, compiled, sizes = _compile(
            lambda s, st, _stage=stage, _o=options: _stage.run(s, st, _o), scene, state
        )
        state = compiled(scene, state)
        rows.append((stage.name, dict(lower=tr + lo, compile=co, **sizes)))
    return rows


# Configs beyond the presets, by name: the default before its IQR, BPE filter and regrouping
# were left out (experiments/RESULTS.md, "Every stage of best()").
VARIANTS = {"former_best": ("best", dict(iqr=True, bpe_filter=True, regroup=True))}


def make_config(name: str, sigma_mode: str) -> Config:
    """A preset (``paper``, ``extended``, ``best``, ...) or one of :data:`VARIANTS`."""
    preset, fields = VARIANTS.get(name, (name, {}))
    return getattr(Config, preset)(sigma_mode=sigma_mode, **fields)


def main(
    presets=("paper", "extended", "best"), sigmas=("given", "auto"), stages: bool = True
) -> None:
    rig, xy, mask = _scene_inputs()
    print(
        f"scene: {mask.shape[0]} views, {int(mask.sum(axis=1).max())} of {mask.shape[1]} slots; {jax.devices()[0].platform}"
    )
    print(
        "\nwhole program        trace  lower compile    cpu  warm ms    ops while |    hlo fusions kernels while"
    )
    for preset in presets:
        for sigma_mode in sigmas:
            config = make_config(preset, sigma_mode)
            r = whole_program(config, rig, xy, mask)
            print(
                f"{preset:>9} σ {sigma_mode:<6} {r['trace']:6.2f} {r['lower']:6.2f} {r['compile']:7.2f} {r['cpu']:6.2f} {r['warm_ms']:8.2f} "
                f"{r['ops']:6d} {r['while']:5d} | {r['hlo']:6d} {r['fusions']:7d} {r['kernels']:7d} {r['hlo_while']:5d}"
            )
    if not stages:
        return
    for preset in presets:
        for sigma_mode in sigmas:
            if preset != "best" and sigma_mode != "given":
                continue
            config = make_config(preset, sigma_mode)
            rows = per_stage(config, rig, xy, mask)
            total = sum(r["cpu"] for _, r in rows)
            print(
                f"\n{preset}(sigma_mode={sigma_mode!r}), each stage alone: trace+lower / compile (s), share of the compile CPU sum ({total:.2f} s)"
            )
            print(
                "stage                 lower compile    cpu  share    ops while |    hlo fusions kernels while"
            )
            for name, r in rows:
                print(
                    f"{name:<20} {r['lower']:6.2f} {r['compile']:7.2f} {r['cpu']:6.2f} {100 * r['cpu'] / total:5.1f}% "
                    f"{r['ops']:6d} {r['while']:5d} | {r['hlo']:6d} {r['fusions']:7d} {r['kernels']:7d} {r['hlo_while']:5d}"
                )


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--presets", default="paper,extended,best")
    parser.add_argument("--sigma", default="given,auto")
    parser.add_argument("--no-stages", action="store_true")
    a = parser.parse_args()
    main(tuple(a.presets.split(",")), tuple(a.sigma.split(",")), not a.no_stages)
