"""Every registered method on the benchmark grid, in the layout of the paper's Tables II–V.

Question: how does each method of the registry (:func:`cdog_jax.method_names`: C-DOG's
presets and the baselines of :mod:`cdog_jax.baselines`, and whatever else is registered
when this runs) score on the docs/BENCHMARK.md §1 grid at σ = 0, 1, 3, 5, beside the paper's
own numbers (docs/BENCHMARK.md §3), and what does it cost per scene?

Method:

1. **Probe.** Each method's warm time per scene (compile apart) is measured on
   ``--probe-scenes`` scenes of the grid's largest point count at σ = 3 with
   :func:`cdog_jax.benchmark.sweep_host` (a jittable method compiled once per bucket, then
   timed scene by scene). A method that refuses such scenes (``exact``: at most 15
   detections per view) is probed at the largest count it accepts, and its sub-grid stops
   there.
2. **Plan.** The per-scene cost at a count is modelled as the probe's time scaled linearly
   with the bucket capacity (an overestimate for the smaller buckets of methods whose cost
   grows faster than linearly), plus the sweep's own timing runs. The first grid of this
   ladder whose estimate fits ``--budget-s`` is chosen: the full grid; the table σ's
   (0, 1, 3, 5) with 5, 3, 2, 1 scenes per cell; then one scene per cell and every k-th
   point count (the largest count kept). The plan is printed before anything runs.
3. **Run.** Jittable methods whose modelled time per scene at the largest count is at
   most :data:`SLOW_S` run through :func:`cdog_jax.benchmark.sweep` (one compiled
   call; time per scene estimated per bucket, warm), the others (slow or host methods) through
   :func:`cdog_jax.benchmark.sweep_host` (time per scene measured, warm). The scenes of a
   sub-grid are the very scenes of the full grid (keys depend on σ, count and scene index
   only).
4. **Cache.** Each method's result is saved under ``--cache`` (default
   ``~/.cache/cdog_jax/compare/``) in a folder named by the method and a hash of its name,
   its ``repr`` (structure and numbers), the package version, the source of the module
   that defines it (for a C-DOG config also of its stages' modules and the package modules
   they use) and of the scene generator and the metrics, the base grid and the
   buckets. A rerun computes only new or changed methods (``--refresh`` recomputes all or the
   named ones).
5. **Report.** One Markdown table per σ (0, 1, 3, 5): one row per method, G-F1, G-IoU,
   mP-P/R/F1/IoU, PG-P/R/F1, 3DErr, BPE and time per scene, averaged over the scenes of that
   σ as :func:`cdog_jax.metrics.mean_metrics` does, the paper's own numbers beneath the rows
   it has (parsed from docs/BENCHMARK.md §3). Figures: metrics against σ and time per scene
   against point count, every method. Written between the markers of the section
   "Every registered method on the benchmark grid" of experiments/RESULTS.md (``--results``;
   ``--quick`` writes nowhere unless given one).

Usage::

    python experiments/compare_methods.py [--methods all|a,b,...] [--quick] [--budget-s 300]
        [--probe-scenes 3] [--cache DIR] [--refresh [a,b,...]] [--plan-only]
        [--figures experiments/figures] [--results experiments/RESULTS.md]
"""

from __future__ import annotations

import argparse
import dataclasses
import gc
import hashlib
import inspect
import json
import math
import os
import re
import sys
import time

import jax
import numpy as np

sys.path.insert(
    0, os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
)  # this checkout's cdog_jax
import cdog_jax  # noqa: E402
from cdog_jax import method_from, method_names  # noqa: E402
from cdog_jax.benchmark import Grid, load_results, print_progress, save_results, sweep, sweep_host  # noqa: E402
from cdog_jax.metrics import mean_metrics  # noqa: E402
from cdog_jax.synthetic import default_rig  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
BUCKETS = (20, 50, 90, 130)
TABLE_SIGMAS = (0.0, 1.0, 3.0, 5.0)
PROBE_SIGMA = 3.0
SLOW_S = 0.1  # modelled seconds per scene at the largest count above which a jittable method runs scene by scene
TIMING_SCENES = 8  # the sweep's timing chunk per bucket (cdog_jax.benchmark._sweep.TIMING_SCENES)
BEGIN, END = "<!-- compare_methods: begin -->", "<!-- compare_methods: end -->"
SECTION = "## Every registered method on the benchmark grid"

# Our registered name → the start of the paper's row name in docs/BENCHMARK.md §3 (the rows
# the paper has; a method without one gets no paper row).
PAPER_ROW = {
    "paper": "Ours",
    "greedy": "Greedy",
    "components": "Connected components",
    "spectral_clustering": "Spectral clustering",
    "spectral_sync": "Permutation synchronisation",
    "soft_ba": "Bundle adjustment with soft matching",
    "st_cut": "ST-cut, 3D back-projection",
}

# Column title, mean_metrics key, format (the paper's Tables II–V, docs/BENCHMARK.md §2).
COLUMNS = (
    ("G-F1", "g_f1", "{:.3f}"),
    ("G-IoU", "g_iou", "{:.3f}"),
    ("mP-P", "mp_p", "{:.3f}"),
    ("mP-R", "mp_r", "{:.3f}"),
    ("mP-F1", "mp_f1", "{:.3f}"),
    ("mP-IoU", "mp_iou", "{:.3f}"),
    ("PG-P", "pg_p", "{:.3f}"),
    ("PG-R", "pg_r", "{:.3f}"),
    ("PG-F1", "pg_f1", "{:.3f}"),
    ("3DErr", "err3d", "{:.3f}"),
    ("BPE (px)", "bpe_px", "{:.2f}"),
    ("time (ms)", "time_ms", "{:.3g}"),
)


def log(*a):
    print(*a, flush=True)


# ----------------------------------------------------------------------------- cache


def _source_hash(*objects) -> str:
    h = hashlib.sha256()
    for obj in objects:
        try:
            with open(inspect.getsourcefile(obj), "rb") as f:
                h.update(f.read())
        except (TypeError, OSError):
            h.update(repr(obj).encode())
    return h.hexdigest()


def _rule_modules(method) -> list:
    """The package modules the stages of a C-DOG config run (none for other methods) and,
    transitively, the package modules they use: the module that defines the config does
    not hold the rules, so a change in a stage's file must change the key too."""
    stages = getattr(type(method), "stages", ())
    todo = [sys.modules[stage.run.__module__] for stage in stages if stage.when(method)]
    seen = {}
    while todo:
        module = todo.pop()
        if module.__name__ in seen:
            continue
        seen[module.__name__] = module
        for value in vars(module).values():
            owner = (
                value.__name__ if inspect.ismodule(value) else getattr(value, "__module__", None)
            )
            if (
                isinstance(owner, str)
                and owner.split(".")[0] == "cdog_jax"
                and owner in sys.modules
            ):
                todo.append(sys.modules[owner])
    return [seen[name] for name in sorted(seen)]


def cache_folder(cache: str, name: str, method, base: Grid) -> str:
    """The cache folder of ``method`` (registered as ``name``) on the base grid ``base``."""
    # The files that generate and score the scenes, reached through their public functions.
    from cdog_jax.metrics import scene_metrics
    from cdog_jax.synthetic import generate_scene

    key = json.dumps(
        {
            "name": name,
            "method": repr(method),
            "version": cdog_jax.__version__,
            "source": _source_hash(
                type(method), *_rule_modules(method), generate_scene, scene_metrics
            ),
            "grid": dataclasses.asdict(base),
            "buckets": BUCKETS,
        },
        sort_keys=True,
    )
    return os.path.join(cache, f"{name}-{hashlib.sha256(key.encode()).hexdigest()[:16]}")


# ----------------------------------------------------------------------------- probe and plan


@dataclasses.dataclass
class Plan:
    name: str
    jittable: bool
    probe_count: int  # the count of the reference probe
    probe_s: float  # median warm time per scene there
    alpha: float  # time ∝ bucket capacity ** alpha (fitted from two probes, else 3)
    max_count: int  # the largest count the method is known to accept
    grid: Grid
    estimate_s: float
    timing_runs: int
    fits: bool
    compiled: bool  # through the compiled sweep (else sweep_host, scene by scene)
    measured_s: float | None = None


def _bucket(count) -> np.ndarray:
    return np.asarray(BUCKETS)[np.searchsorted(np.asarray(BUCKETS), np.asarray(count), side="left")]


def _probe_at(rig, name, method, base: Grid, count: int, scenes: int) -> float | None:
    """Median warm time per scene at ``count`` (σ = :data:`PROBE_SIGMA`), None if refused."""
    grid = base.replace(sigmas=(PROBE_SIGMA,), counts=(count,), scenes=scenes)
    try:
        res = sweep_host(rig, grid, {name: method}, buckets=BUCKETS)
    except ValueError as err:
        if f"sweep_host (method {name!r}, scene" in str(err):
            return None  # refused at this size
        raise
    return float(np.median(res.time_s[name]))


def probe(rig, name, method, base: Grid, scenes: int, budget_s: float):
    """``(count, seconds, alpha, max_count)``: a probe at the largest count of the smallest
    bucket the method accepts, then, unless that predicts (cubic growth) a probe costing more
    than a tenth of the budget, at the grid's largest count it accepts; ``alpha`` the
    growth exponent of the time with the bucket capacity between the two (3 if one probe)."""
    small = None
    for count in sorted((c for c in base.counts if c <= BUCKETS[0]), reverse=True):
        t = _probe_at(rig, name, method, base, count, scenes)
        if t is not None:
            small = (count, t)
            break
    if small is None:
        raise ValueError(f"{name}: refuses the probe scenes at every count ≤ {BUCKETS[0]}")
    larger = sorted((c for c in base.counts if c > small[0]), reverse=True)
    if not larger:
        return small[0], small[1], 1.0, small[0]
    predicted = small[1] * (float(_bucket(larger[0])) / float(_bucket(small[0]))) ** 3
    if (scenes + 1) * predicted > 0.1 * budget_s:
        log(
            f"  {name}: {1e3 * small[1]:.3g} ms per scene at count {small[0]}; not probed at {larger[0]} "
            f"(predicted {predicted:.1f} s per scene)"
        )
        return small[0], small[1], 3.0, small[0] if not method.jittable else max(base.counts)
    for count in larger:
        t = _probe_at(rig, name, method, base, count, scenes)
        if t is not None:
            ratio = float(_bucket(count)) / float(_bucket(small[0]))
            alpha = (
                1.0
                if ratio == 1.0
                else float(np.clip(np.log(max(t, 1e-9) / small[1]) / np.log(ratio), 0.5, 3.0))
            )
            return count, t, alpha, count
    return small[0], small[1], 1.0, small[0]


def per_scene_s(counts, plan_count: int, plan_s: float, alpha: float) -> np.ndarray:
    """Modelled seconds per scene at each count: the probe's time scaled by bucket capacity."""
    return plan_s * (_bucket(counts).astype(np.float64) / float(_bucket(plan_count))) ** alpha


def estimate(
    grid: Grid, probe_count: int, probe_s: float, alpha: float, compiled: bool, timing_runs: int
) -> float:
    """Seconds to run ``grid`` (the model of :func:`per_scene_s`, compiles apart), plus per
    bucket the compiled sweep's warm-up and timing runs of one chunk, or sweep_host's one
    warm-up scene."""
    per_count = per_scene_s(grid.counts, probe_count, probe_s, alpha)
    total = float(np.sum(per_count) * len(grid.sigmas) * grid.scenes)
    buckets = _bucket(grid.counts)
    for b in np.unique(buckets):
        n = int(np.sum(buckets == b)) * len(grid.sigmas) * grid.scenes
        extra = (timing_runs + 1) * min(TIMING_SCENES, n) if compiled else 1
        total += extra * float(per_count[buckets == b][0])
    return total


def ladder(base: Grid, max_count: int) -> list[Grid]:
    """Candidate grids, largest first (see the module docstring)."""
    counts = tuple(c for c in base.counts if c <= max_count)
    table = (
        tuple(s for s in base.sigmas if any(abs(s - t) < 5e-4 for t in TABLE_SIGMAS)) or base.sigmas
    )
    out = [base.replace(counts=counts)]
    for n in sorted({k for k in (base.scenes, 3, 2, 1) if k <= base.scenes}, reverse=True):
        out.append(base.replace(sigmas=table, counts=counts, scenes=n))
    for k in (2, 3, 4, 6, 8, 14):
        sub = tuple(counts[::-1][::k][::-1])
        if len(sub) < len(out[-1].counts):
            out.append(base.replace(sigmas=table, counts=sub, scenes=1))
    for top in sorted({c for c in counts if c in BUCKETS or c in (10, 5)}, reverse=True):
        if top < max(counts):
            out.append(
                base.replace(sigmas=table, counts=tuple(c for c in counts if c <= top), scenes=1)
            )
    return out


def make_plan(rig, name, method, base: Grid, budget_s: float, probe_scenes: int) -> Plan:
    count, t, alpha, max_count = probe(rig, name, method, base, probe_scenes, budget_s)
    runs = 3 if t < 0.05 else 1
    # Slow jittable methods run scene by scene too: the probe measured that path, its
    # compiles are cheaper than the sweep's, and each scene's time is its own.
    compiled = method.jittable and float(per_scene_s(max(base.counts), count, t, alpha)) <= SLOW_S
    candidates = ladder(base, max_count)
    for grid in candidates:
        est = estimate(grid, count, t, alpha, compiled, runs)
        if est <= budget_s:
            return Plan(
                name, method.jittable, count, t, alpha, max_count, grid, est, runs, True, compiled
            )
    return Plan(
        name,
        method.jittable,
        count,
        t,
        alpha,
        max_count,
        candidates[-1],
        est,
        runs,
        False,
        compiled,
    )


def describe_grid(grid: Grid, base: Grid) -> str:
    if grid == base:
        return f"full grid ({grid.num_scenes} scenes)"
    parts = []
    if grid.sigmas != base.sigmas:
        parts.append("σ ∈ {" + ", ".join(f"{s:g}" for s in grid.sigmas) + "}")
    if grid.counts != base.counts:
        c = grid.counts
        if c == tuple(x for x in base.counts if x <= max(c)):
            parts.append(f"counts ≤ {max(c)}")
        else:
            parts.append("counts {" + ", ".join(str(x) for x in c) + "}")
    if grid.scenes != base.scenes:
        parts.append(f"scenes 0…{grid.scenes - 1} of each cell")
    return "sub-grid: " + ", ".join(parts) + f" ({grid.num_scenes} scenes)"


# ----------------------------------------------------------------------------- run


def run_method(rig, name, method, plan: Plan):
    if plan.compiled:
        return sweep(
            rig,
            plan.grid,
            methods={name: method},
            buckets=BUCKETS,
            timing_runs=plan.timing_runs,
            progress=print_progress,
        )
    grid = plan.grid
    while True:  # a host method may refuse a scene the probe did not see: drop that count
        try:
            return sweep_host(rig, grid, {name: method}, buckets=BUCKETS)
        except ValueError as err:
            if f"sweep_host (method {name!r}, scene" not in str(err) or len(grid.counts) == 1:
                raise
            log(f"  {name}: refuses a scene at count {max(grid.counts)}; dropping that count")
            grid = grid.replace(counts=grid.counts[:-1])
            plan.grid = grid


# ----------------------------------------------------------------------------- report


def paper_numbers(
    path: str,
) -> tuple[dict[float, dict[str, float]], dict[str, dict[float, dict[str, float]]]]:
    """docs/BENCHMARK.md §3: the paper's C-DOG row per σ ``{σ: {key: value}}`` and its
    baselines ``{row name: {σ: {"pg_f1": …, "g_f1": …}}}``."""
    text = open(path, encoding="utf-8").read()
    sec = text.split("## 3.", 1)[1].split("\n## ", 1)[0]
    ours, baselines = {}, {}
    keys = {
        "G-F1": "g_f1",
        "mP-F1": "mp_f1",
        "PG-P": "pg_p",
        "PG-R": "pg_r",
        "PG-F1": "pg_f1",
        "3DErr": "err3d",
        "BPE": "bpe_px",
        "time (ms)": "time_ms",
    }
    header = None
    for line in sec.splitlines():
        if not line.startswith("|") or line.startswith("|---"):
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells[0] in ("σ (px)", "method"):
            header = cells
            continue
        if header and header[0] == "σ (px)":
            ours[float(cells[0])] = {
                keys[h]: float(v) for h, v in zip(header[1:], cells[1:]) if h in keys
            }
        elif header and header[0] == "method":
            row = {}
            for h, v in zip(header[1:], cells[1:]):
                sigma = float(re.search(r"σ = ([\d.]+)", h).group(1))
                pg, g = (float(x) for x in v.split("/"))
                row[sigma] = {"pg_f1": pg, "g_f1": g}
            baselines[cells[0]] = row
    return ours, baselines


def paper_row_for(name: str, ours, baselines) -> tuple[str, dict[float, dict[str, float]]] | None:
    start = PAPER_ROW.get(name)
    if start is None:
        return None
    if start == "Ours":
        return "the paper's C-DOG (“Ours”)", ours
    for row, values in baselines.items():
        if row.startswith(start):
            return f"the paper's {row}", values
    return None


def _cells(means: dict[str, float]) -> list[str]:
    out = []
    for _, key, fmt in COLUMNS:
        v = means.get(key)
        out.append("–" if v is None or (isinstance(v, float) and math.isnan(v)) else fmt.format(v))
    return out


def _at_table_sigmas(grid: Grid) -> Grid:
    keep = (
        tuple(s for s in grid.sigmas if any(abs(s - t) < 5e-4 for t in TABLE_SIGMAS)) or grid.sigmas
    )
    return grid.replace(sigmas=keep)


def tables(results: dict, plans: dict[str, Plan], base: Grid, ours, baselines) -> str:
    # A sub-grid that only leaves out σ levels has, at the tables' σ, the full grid's scenes:
    # no mark there (the figures still say sub-grid).
    marks = {}
    for name in results:
        if _at_table_sigmas(plans[name].grid) != _at_table_sigmas(base):
            marks[name] = "ᵃᵇᶜᵈᵉᶠᵍʰⁱʲᵏˡᵐⁿᵒᵖ"[len(marks) % 16]
    head = ["method", *(c[0] for c in COLUMNS), "scenes"]
    lines = []
    for sigma in TABLE_SIGMAS:
        if not any(abs(sigma - s) < 5e-4 for s in base.sigmas):
            continue
        lines += [
            f"**σ = {sigma:g} px**",
            "",
            "| " + " | ".join(head) + " |",
            "|" + "---|" * len(head),
        ]
        for name, res in results.items():
            where = np.isclose(res.sigma, sigma, rtol=0.0, atol=5e-4)
            if not where.any():
                lines.append(
                    f"| {name}{marks.get(name, '')} | "
                    + " | ".join(["–"] * (len(COLUMNS) + 1))
                    + " |"
                )
                continue
            means = mean_metrics(res.metrics_of(name, where=where))
            means["time_ms"] = 1000.0 * float(np.mean(res.time_s[name][where]))
            lines.append(
                f"| {name}{marks.get(name, '')} | "
                + " | ".join(_cells(means))
                + f" | {int(where.sum())} |"
            )
            paper = paper_row_for(name, ours, baselines)
            if paper is not None and sigma in paper[1]:
                lines.append(
                    f"| ↳ *{paper[0]}* | " + " | ".join(_cells(paper[1][sigma])) + " | full grid |"
                )
        lines.append("")
    notes = [
        f"{mark} {name}: {describe_grid(plans[name].grid, base)}" for name, mark in marks.items()
    ]
    if notes:
        lines += [
            "Methods marked run on a sub-grid (the same scenes as the full grid's, fewer of them; the "
            "tables below compare them with the full-grid methods on exactly their scenes):",
            "",
        ]
        lines += [f"- {n}" for n in notes] + [""]
    sigma_only = [n for n in results if plans[n].grid != base and n not in marks]
    if sigma_only:
        lines += [
            f"{', '.join(sigma_only)}: σ ∈ {{0, 1, 3, 5}} only (every count, every scene): at these σ the "
            "full grid's scenes, so their rows above are full-grid numbers; their lines in the figure "
            "have four points.",
            "",
        ]
    return "\n".join(lines)


def _scene_ids(res) -> np.ndarray:
    """``(S,)`` int64 names of a result's scenes (σ in milli-pixels, count, scene index)."""
    milli = np.round(1000.0 * res.sigma).astype(np.int64)
    return (milli * 1000 + res.count.astype(np.int64)) * 1000 + res.scene.astype(np.int64)


def same_scenes_tables(results: dict, plans: dict[str, Plan], base: Grid) -> str:
    """For every sub-grid method: it and every full-grid method on exactly its scenes, PG-F1 /
    G-F1 at each table σ (the like-for-like comparison the main tables cannot give)."""
    full = [n for n in results if _at_table_sigmas(plans[n].grid) == _at_table_sigmas(base)]
    lines = []
    for sub in (n for n in results if n not in full):
        ids = _scene_ids(results[sub])
        sigmas = [t for t in TABLE_SIGMAS if np.isclose(results[sub].sigma, t, atol=5e-4).any()]
        lines += [
            f"On the scenes of {sub} ({describe_grid(plans[sub].grid, base)}), PG-F1 / G-F1:",
            "",
            "| method | " + " | ".join(f"σ = {t:g}" for t in sigmas) + " |",
            "|---|" + "---|" * len(sigmas),
        ]
        for name in [sub, *full]:
            res = results[name]
            on = np.isin(_scene_ids(res), ids)
            cells = []
            for t in sigmas:
                where = on & np.isclose(res.sigma, t, rtol=0.0, atol=5e-4)
                m = mean_metrics(res.metrics_of(name, where=where))
                cells.append(f"{m['pg_f1']:.3f} / {m['g_f1']:.3f}")
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)


def plan_table(plans: dict[str, Plan], base: Grid, budget_s: float) -> str:
    lines = [
        f"| method | runs | probe: ms per scene (count, σ = {PROBE_SIGMA:g}) | growth exponent | grid run | estimate (s) | measured (s) |",
        "|---|---|---|---|---|---|---|",
    ]
    for p in plans.values():
        where = (
            "compiled sweep"
            if p.compiled
            else ("jitted, " if p.jittable else "host, ") + "scene by scene (sweep_host)"
        )
        fit = "" if p.fits else f" (over the {budget_s:g} s budget even at its smallest)"
        measured = "–" if p.measured_s is None else f"{p.measured_s:.0f}"
        lines.append(
            f"| {p.name} | {where} | {1e3 * p.probe_s:.3g} ({p.probe_count}) | {p.alpha:.2f} | "
            f"{describe_grid(p.grid, base)}{fit} | {p.estimate_s:.0f} | {measured} |"
        )
    return "\n".join(lines)


def figures(results: dict, base: Grid, out_dir: str, prefix: str) -> list[str]:
    from cdog_jax.viz import metrics_vs_sigma, time_vs_count

    os.makedirs(out_dir, exist_ok=True)
    label = {n: n if results[n].grid == base else f"{n} (sub-grid)" for n in results}
    sigma = {label[n]: r.sigma for n, r in results.items()}
    count = {label[n]: r.count for n, r in results.items()}
    capacity = {label[n]: r.capacity for n, r in results.items()}
    metrics = {label[n]: r.metrics[n] for n, r in results.items()}
    full = all(r.grid == base for r in results.values()) and base == Grid.paper()
    p1 = os.path.join(out_dir, f"{prefix}metrics_vs_sigma.png")
    metrics_vs_sigma(sigma, metrics, full_grid=full, path=p1)
    p2 = os.path.join(out_dir, f"{prefix}time_vs_count.png")
    time_vs_count(
        count, {label[n]: r.time_s[n] for n, r in results.items()}, capacity=capacity, path=p2
    )
    return [p1, p2]


def write_section(path: str, body: str) -> None:
    text = open(path, encoding="utf-8").read() if os.path.exists(path) else "# Results\n"
    block = f"{BEGIN}\n{body.rstrip()}\n{END}"
    if BEGIN in text and END in text:
        head, rest = text.split(BEGIN, 1)
        text = head + block + rest.split(END, 1)[1]
    else:
        text = text.rstrip() + f"\n\n{SECTION}\n\n{block}\n"
    with open(path, "w", encoding="utf-8") as f:
        f.write(text)


# ----------------------------------------------------------------------------- main


def main(argv=None):
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument(
        "--methods", default="all", help="'all' (every registered method) or a comma-separated list"
    )
    ap.add_argument(
        "--quick", action="store_true", help="the small grid of Grid.quick() (a smoke run)"
    )
    ap.add_argument(
        "--budget-s",
        type=float,
        default=300.0,
        help="compute budget per method (s), sets sub-grids",
    )
    ap.add_argument("--probe-scenes", type=int, default=3)
    ap.add_argument(
        "--cache", default=os.path.join(os.path.expanduser("~"), ".cache", "cdog_jax", "compare")
    )
    ap.add_argument(
        "--refresh",
        nargs="?",
        const="all",
        default="",
        help="recompute even when cached: every method, or a comma-separated list",
    )
    ap.add_argument(
        "--plan-only", action="store_true", help="probe and print the plan, run nothing"
    )
    ap.add_argument(
        "--figures", default=None, help="figure folder (default experiments/figures; --quick: none)"
    )
    ap.add_argument(
        "--results",
        default=None,
        help="Markdown file to write the section into "
        "(default experiments/RESULTS.md; --quick: none)",
    )
    args = ap.parse_args(argv)

    names = (
        list(method_names())
        if args.methods == "all"
        else [m.strip() for m in args.methods.split(",") if m.strip()]
    )
    methods = {n: method_from(n, "compare_methods --methods") for n in names}
    base = Grid.quick() if args.quick else Grid.paper()
    figures_dir = args.figures or (None if args.quick else os.path.join(HERE, "figures"))
    results_md = args.results or (None if args.quick else os.path.join(HERE, "RESULTS.md"))
    rig = default_rig()
    log(
        f"methods: {', '.join(names)}; base grid: {base.num_scenes} scenes; budget {args.budget_s:g} s per method"
    )

    plans, results, folders = {}, {}, {}
    for name, method in methods.items():
        folders[name] = folder = cache_folder(args.cache, name, method, base)
        refresh = args.refresh == "all" or name in args.refresh.split(",")
        if not refresh and os.path.exists(os.path.join(folder, "plan.json")):
            with open(os.path.join(folder, "plan.json")) as f:
                saved = json.load(f)
            saved["grid"] = Grid(
                **{k: tuple(v) if isinstance(v, list) else v for k, v in saved["grid"].items()}
            )
            saved.setdefault("compiled", saved["jittable"])  # plans saved before that field
            plans[name] = Plan(**saved)
            results[name] = load_results(folder)
            log(f"{name}: cached ({describe_grid(plans[name].grid, base)})")
            continue
        t0 = time.perf_counter()
        plans[name] = make_plan(rig, name, method, base, args.budget_s, args.probe_scenes)
        log(
            f"{name}: probe {1e3 * plans[name].probe_s:.3g} ms per scene at count {plans[name].probe_count} "
            f"({time.perf_counter() - t0:.1f} s with compiles) -> {describe_grid(plans[name].grid, base)}, "
            f"estimate {plans[name].estimate_s:.0f} s"
        )
        release_programs()
    log("\nPlan:\n" + plan_table(plans, base, args.budget_s) + "\n")
    if args.plan_only:
        return plans

    for name, method in methods.items():
        if name in results:
            continue
        log(f"running {name} on {describe_grid(plans[name].grid, base)} ...")
        t0 = time.perf_counter()
        res = run_method(rig, name, method, plans[name])
        plans[name].measured_s = time.perf_counter() - t0
        log(f"  {name}: {plans[name].measured_s:.1f} s (compile {res.compile_s:.1f} s)")
        save_results(res, folders[name])
        with open(os.path.join(folders[name], "plan.json"), "w") as f:
            json.dump(
                {**dataclasses.asdict(plans[name]), "grid": dataclasses.asdict(plans[name].grid)},
                f,
                indent=1,
            )
        results[name] = res
        release_programs()
    # Tables and figures in the methods' registered order, cached or run now.
    plans, results = ({name: d[name] for name in methods} for d in (plans, results))

    ours, baselines = paper_numbers(os.path.join(ROOT, "docs", "BENCHMARK.md"))
    body = [
        f"Command: `python experiments/compare_methods.py{' --quick' if args.quick else ''} --budget-s {args.budget_s:g}` "
        f"({len(results)} methods, every one registered; base grid {describe_grid(base, base)}, "
        f"buckets {'/'.join(map(str, BUCKETS))}; {next(iter(results.values())).device}, "
        f"JAX {next(iter(results.values())).versions['jax']}). Time: warm association time per scene, compile apart "
        "(compiled sweep: one chunk per bucket timed, the bucket's per-scene time; host methods: each scene timed), "
        "mean over the σ's scenes.",
        "",
        "Plan (probe and budget per method):",
        "",
        plan_table(plans, base, args.budget_s),
        "",
        tables(results, plans, base, ours, baselines),
        same_scenes_tables(results, plans, base),
    ]
    if figures_dir:
        paths = figures(results, base, figures_dir, "compare_")
        rel = [os.path.relpath(p, os.path.dirname(results_md)) if results_md else p for p in paths]
        body += ["Figures (every method; a sub-grid method's line averages its own scenes):", ""]
        body += [f"![{os.path.basename(p)}]({p})" for p in rel] + [""]
    text = "\n".join(body)
    print(text)
    if results_md:
        write_section(results_md, text)
        log(f"wrote the section into {results_md}")
    return results


def release_programs() -> None:
    """Drop every compiled program once a method is done with them. Each holds its own
    memory maps for code; thirteen methods' probes and sweeps kept alive in one process
    passed the kernel's limit (65,530), and XLA then aborted while compiling ("Cannot
    allocate memory")."""
    jax.clear_caches()
    gc.collect()


if __name__ == "__main__":
    sys.exit(0 if main() is not None else 1)
