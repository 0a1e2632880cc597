"""Robustness of C-DOG to missed detections and to clutter (docs/BENCHMARK.md §1, beyond the paper).

Question: how do PG-F1, mP-F1 and G-F1 fall when detections are missed (drop rate 0, 5, 10,
20, 30 %) or when false detections are added (Poisson clutter, mean 0, 2, 5, 10, 20 points
per view), at σ = 1 px, for ``Config.paper()``, ``Config.reference()`` and
``Config.extended()``; and what does the visibility-support filter
(``support_filter=True``, off in every preset) change for ``paper()`` and ``extended()``?

Method: built-in 10-camera rig (``cdog_jax.synthetic.default_rig()``), σ = 1 px; for every
level, ``--scenes`` scenes of each point count in ``--counts`` (default 20, 60, 100). One
batch of scenes is drawn with :func:`cdog_jax.synthetic.generate_scenes` (per-scene, traced
drop and clutter rates; ``capacity`` = the largest count, ``clutter_capacity`` = 44 so that
a Poisson(20) count is clipped with probability ≈ 10⁻⁶; the clipped count is checked). The
two sweeps share the level (0 %, 0). Which points exist is decided before the drops (a
point visible in ≥ 2 views), so every drop rate keeps the same points, and a point may
be left with one detection (then it is no ground-truth group, docs/BENCHMARK.md §2). Each config
associates the whole batch in one compiled :func:`cdog_jax.associate_batch` call (σ given,
the rates only change the data, so nothing recompiles); the metrics are
:func:`cdog_jax.metrics.scene_metrics` vmapped, means over scenes as
:func:`cdog_jax.metrics.mean_metrics`. "truth G-F1" is the G-F1 of the true grouping (one
group per ground-truth group, everything else unassigned): every unassigned detection is a
singleton prediction (docs/BENCHMARK.md §2), so clutter and points seen once keep G-F1 below 1 even for
the truth (its PG-F1 and mP-F1 are 1). A method can score above it by hiding clutter inside
correct groups (a group stays a G- match while its majority is right).

``--methods`` (default ``all``: the configs above, then every registered method, e.g. the
baselines of :mod:`cdog_jax.baselines`) picks the methods. Scenes run 8 at a time, scene 0
of every (level, count) first; with ``--budget-s`` a method stops after that many seconds
(past its compiling first chunk), so a slow one covers the first scenes of every cell; a
method skips scenes it refuses (``exact``: more than 15 detections per view). The tables
then say how many scenes each such method ran per level.

``--stages`` adds the per-stage view of ``experiments/stage_ablation.py`` (cumulative
configs) at the largest drop rate and the largest clutter level: how many ground-truth
groups survive each stage (PG-R) and how precise the groups are (PG-P).

Usage::

    python experiments/robustness.py [--counts 20 60 100] [--scenes 8] [--stages] [--methods all|a,b] [--budget-s S]
        [--figure experiments/figures/robustness.png] [--json out.json] [--quick]

Writes the two-panel figure (``--figure``), optionally the numbers as JSON (``--json``), and
prints Markdown tables.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import jax
import jax.numpy as jnp
import numpy as np

from cdog_jax import Config, associate_batch, method_from, method_names
from cdog_jax.benchmark import ablation_stages
from cdog_jax.metrics import scene_metrics
from cdog_jax.synthetic import default_rig, generate_scenes

SIGMA = 1.0
DROP_RATES = (0.0, 0.05, 0.1, 0.2, 0.3)
CLUTTER_RATES = (0.0, 2.0, 5.0, 10.0, 20.0)
CLUTTER_CAPACITY = 44  # > 20 + 5 √20: P(Poisson(20) ≥ 44) ≈ 1e-6
FIELDS = ("pg_f1", "mp_f1", "g_f1", "pg_p", "pg_r", "num_unassigned")
CONFIGS = {
    "paper": Config.paper(),
    "reference": Config.reference(),
    "extended": Config.extended(),
    # The improvement: drop groups that views seeing their point do not detect.
    "paper+support": Config.paper(support_filter=True),
    "extended+support": Config.extended(support_filter=True),
}
# The cumulative stages of stage_ablation.py (one list, so the two tables stay comparable),
# plus the filter this experiment motivated.
STAGES = {**ablation_stages(), "+ support filter": Config.extended(support_filter=True)}

_metrics_batch = jax.jit(jax.vmap(scene_metrics, in_axes=(None, 0, 0)))
CHUNK = 8  # scenes per associate_batch call (one compiled shape per method)


def all_methods() -> dict:
    """:data:`CONFIGS`, then every registered method not among them (the registry as it is
    when this runs)."""
    out = dict(CONFIGS)
    for name in method_names():
        if name not in out:
            out[name] = method_from(name, "robustness --methods")
    return out


def levels():
    """The (drop rate, clutter rate) levels: the drop sweep, then the clutter sweep (the
    clean level is shared)."""
    return [(d, 0.0) for d in DROP_RATES] + [(0.0, c) for c in CLUTTER_RATES[1:]]


def make_scenes(rig, counts, scenes, seed):
    """One batch: every level × count × scene; returns the scenes and their (drop, clutter)."""
    lv = levels()
    drop = np.repeat([d for d, _ in lv], len(counts) * scenes)
    clutter = np.repeat([c for _, c in lv], len(counts) * scenes)
    count = np.tile(np.repeat(counts, scenes), len(lv))
    batch = generate_scenes(
        jax.random.PRNGKey(seed),
        rig,
        jnp.asarray(count, jnp.int32),
        jnp.full(count.shape, SIGMA, jnp.float32),
        capacity=int(max(counts)),
        drop_rate=jnp.asarray(drop, jnp.float32),
        clutter_rate=jnp.asarray(clutter, jnp.float32),
        clutter_capacity=CLUTTER_CAPACITY,
    )
    return batch, drop, clutter, count


def truth_g_f1(batch):
    """G-F1 of the perfect association per scene: 2 gt / (2 gt + singletons)."""
    inst, mask = np.asarray(batch.instance), np.asarray(batch.mask)
    out = []
    for b in range(inst.shape[0]):
        ids = inst[b][mask[b] & (inst[b] >= 0)]
        n = np.bincount(ids, minlength=1) if ids.size else np.zeros(1, int)
        gt = int(np.sum(n >= 2))
        singles = int(mask[b].sum()) - int(n[n >= 2].sum())
        out.append(2 * gt / (2 * gt + singles) if gt else 0.0)
    return np.asarray(out)


def evaluate(rig, batch, configs, log=print, budget_s=None, order=None):
    """Per-scene metrics ``{name: {field: (S,)}}`` of every config (NaN for a scene not run).

    Scenes run :data:`CHUNK` at a time in ``order`` (default: as given; pass scene index
    first so that a partial run covers every level and count alike). With ``budget_s`` a
    method stops starting chunks once it has spent that many seconds after its first
    (compiling) chunk. Scenes a method refuses (``check_scene``, e.g. ``exact`` beyond 15
    detections per view) are skipped."""
    S = int(batch.mask.shape[0])
    order = np.arange(S) if order is None else np.asarray(order)
    mask = np.asarray(batch.mask)
    out = {}
    for name, config in configs.items():
        method = method_from(config, "robustness")
        t0 = time.perf_counter()
        ok = []
        for s in order:
            try:
                method.check_scene(mask[s], f"robustness (scene {s})")
                ok.append(s)
            except ValueError:
                pass
        ok = np.asarray(ok, np.int64)
        fields = {f: np.full(S, np.nan) for f in FIELDS}
        t_first, done = None, 0
        for start in range(0, ok.size, CHUNK):
            if (
                budget_s is not None
                and t_first is not None
                and time.perf_counter() - t_first > budget_s
            ):
                break
            idx = ok[start : start + CHUNK]
            pad = np.concatenate([idx, np.repeat(idx[:1], CHUNK - idx.size)])  # one compiled shape
            sub = jax.tree.map(lambda a: a[pad], batch)
            assoc = associate_batch(
                rig, sub.xy, sub.mask, method=method, sigma=SIGMA, batch_size=CHUNK
            )
            m = _metrics_batch(rig, assoc, sub)
            for f in FIELDS:
                fields[f][idx] = np.asarray(getattr(m, f), np.float64)[: idx.size]
            done += idx.size
            if t_first is None:
                t_first = time.perf_counter()
        out[name] = fields
        log(
            f"  {name}: {done}/{S} scenes ({S - ok.size} refused), {time.perf_counter() - t0:.1f} s (compile included)"
        )
    return out


def summarise(per_scene, drop, clutter, g_max):
    """Rows ``{drop, clutter, g_f1_max, <config>: {field: mean}}`` per level."""
    rows = []
    for d, c in levels():
        at = (drop == d) & (clutter == c)
        row = {
            "drop_rate": d,
            "clutter_rate": c,
            "num_scenes": int(at.sum()),
            "g_f1_max": float(g_max[at].mean()),
        }
        for name, fields in per_scene.items():
            run = at & np.isfinite(fields["pg_f1"])
            row[name] = {
                f: float(v[run].mean()) if run.any() else float("nan") for f, v in fields.items()
            }
            row[name]["scenes_run"] = int(run.sum())
            # The true grouping's G-F1 on the same scenes, for a method run on a subset.
            row[name]["g_f1_max"] = float(g_max[run].mean()) if run.any() else float("nan")
        rows.append(row)
    return rows


def run(
    *,
    counts=(20, 60, 100),
    scenes=8,
    seed=0,
    stages=False,
    configs=tuple(CONFIGS),
    budget_s=None,
    log=print,
):
    rig = default_rig()
    known = all_methods()
    counts = tuple(int(c) for c in counts)
    t_all = time.perf_counter()
    batch, drop, clutter, count = make_scenes(rig, counts, scenes, seed)
    num_clutter = np.asarray(batch.num_clutter)
    clipped = int(np.sum(num_clutter >= CLUTTER_CAPACITY))
    log(
        f"{drop.size} scenes ({len(levels())} levels × {len(counts)} counts × {scenes}); "
        f"views with clipped clutter: {clipped}"
    )
    scene_index = np.tile(np.arange(scenes), drop.size // scenes)
    order = np.lexsort(
        (np.arange(drop.size), scene_index)
    )  # scene 0 of every cell first, then 1, …
    per_scene = evaluate(
        rig, batch, {name: known[name] for name in configs}, log=log, budget_s=budget_s, order=order
    )
    out = {
        "sigma_px": SIGMA,
        "counts": list(counts),
        "scenes_per_cell": scenes,
        "seed": seed,
        "clutter_capacity": CLUTTER_CAPACITY,
        "clipped_views": clipped,
        "mean_clutter": {str(c): float(num_clutter[clutter == c].mean()) for c in CLUTTER_RATES},
        "configs": list(configs),
        "budget_s": budget_s,
        "rows": summarise(per_scene, drop, clutter, truth_g_f1(batch)),
    }
    if stages:
        worst = (
            (drop == max(DROP_RATES))
            | (clutter == max(CLUTTER_RATES))
            | ((drop == 0) & (clutter == 0))
        )
        sub = jax.tree.map(lambda a: a[worst], batch)
        st = evaluate(rig, sub, STAGES, log=log)
        rows = []
        for d, c in ((0.0, 0.0), (max(DROP_RATES), 0.0), (0.0, max(CLUTTER_RATES))):
            at = (drop[worst] == d) & (clutter[worst] == c)
            for name, fields in st.items():
                rows.append(
                    {
                        "drop_rate": d,
                        "clutter_rate": c,
                        "stage": name,
                        **{f: float(v[at].mean()) for f, v in fields.items()},
                    }
                )
        out["stages"] = rows
    out["total_seconds"] = time.perf_counter() - t_all
    return out


def _cell(v: float) -> str:
    return "–" if v != v else f"{v:.3f}"


def markdown_tables(out: dict) -> str:
    """One table per score (PG-F1, mP-F1, G-F1; rows: levels, columns: configs), then the
    per-stage table when there is one."""
    names = out["configs"]
    lines = []
    for f, label in (("pg_f1", "PG-F1"), ("mp_f1", "mP-F1"), ("g_f1", "G-F1")):
        head = ["drop (%)", "clutter / view"] + [f"{n} {label}" for n in names]
        if f == "g_f1":
            head.append("truth G-F1")
        lines += ["", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for r in out["rows"]:
            cells = [f"{100 * r['drop_rate']:g}", f"{r['clutter_rate']:g}"] + [
                _cell(r[n][f]) for n in names
            ]
            if f == "g_f1":
                cells.append(f"{r['g_f1_max']:.3f}")
            lines.append("| " + " | ".join(cells) + " |")
    partial = [n for n in names if any(r[n]["scenes_run"] < r["num_scenes"] for r in out["rows"])]
    if partial:
        lines += [
            "",
            "Run on part of the scenes (a time budget of "
            f"{out.get('budget_s')} s per method after its first chunk, or scenes it refuses), scenes run per "
            "level of "
            + str(out["rows"][0]["num_scenes"])
            + ", and the true grouping's G-F1 on those scenes:",
            "",
        ]
        for n in partial:
            runs = ", ".join(f"{r[n]['scenes_run']}" for r in out["rows"])
            truth = ", ".join(_cell(r[n]["g_f1_max"]) for r in out["rows"])
            lines.append(f"- {n}: {runs} (truth G-F1 {truth})")
    if "stages" in out:
        lines += [
            "",
            "| drop (%) | clutter / view | stages | PG-R | PG-P | PG-F1 | G-F1 | unassigned / scene |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for r in out["stages"]:
            lines.append(
                f"| {100 * r['drop_rate']:g} | {r['clutter_rate']:g} | {r['stage']} | {r['pg_r']:.3f} | "
                f"{r['pg_p']:.3f} | {r['pg_f1']:.3f} | {r['g_f1']:.3f} | {r['num_unassigned']:.1f} |"
            )
    return "\n".join(lines[1:])


def figure(out: dict, path: str):
    """Two panels (vs drop rate, vs clutter): colour = config, line style = score."""
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    fig = Figure(figsize=(11, 4.6), layout="constrained")
    axes = fig.subplots(1, 2, sharey=True)
    styles = {"pg_f1": ("-", "PG-F1"), "mp_f1": ("--", "mP-F1"), "g_f1": (":", "G-F1")}
    from matplotlib import colormaps

    cmap = colormaps["tab10" if len(out["configs"]) <= 10 else "tab20"]
    colors = {n: cmap(i % cmap.N) for i, n in enumerate(out["configs"])}
    rows = out["rows"]
    sweeps = (
        (
            [r for r in rows if r["clutter_rate"] == 0],
            "drop_rate",
            100.0,
            "missed detections: drop rate (%)",
        ),
        (
            [r for r in rows if r["drop_rate"] == 0],
            "clutter_rate",
            1.0,
            "clutter: mean false detections per view (Poisson mean)",
        ),
    )
    for ax, (sel, key, scale, xlabel) in zip(axes, sweeps):
        x = [scale * r[key] for r in sel]
        for name in out["configs"]:
            for f, (ls, _) in styles.items():
                ax.plot(x, [r[name][f] for r in sel], ls, marker="o", ms=3, color=colors[name])
        ax.plot(x, [r["g_f1_max"] for r in sel], color="0.4", lw=1.2, ls=(0, (1, 3)))
        ax.set_xlabel(xlabel)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("score, mean over scenes (0–1)")
    axes[0].set_title(f"σ = {out['sigma_px']:g} px, no clutter")
    axes[1].set_title(f"σ = {out['sigma_px']:g} px, no missed detections")
    by_config = [Line2D([], [], color=colors[n], lw=2, label=n) for n in out["configs"]]
    by_score = [Line2D([], [], color="k", ls=ls, label=lab) for ls, lab in styles.values()]
    by_score.append(
        Line2D([], [], color="0.4", lw=1.2, ls=(0, (1, 3)), label="G-F1 of the true grouping")
    )
    # The lower part of the drop panel is empty: both legends go there.
    axes[0].add_artist(
        axes[0].legend(
            handles=by_config, fontsize=8, loc="lower left", title="config", title_fontsize=8
        )
    )
    axes[0].legend(handles=by_score, fontsize=8, loc="lower right", title="score", title_fontsize=8)
    fig.savefig(path, dpi=120)
    return fig


def main(argv=None):
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--counts", type=int, nargs="+", default=[20, 60, 100])
    parser.add_argument("--scenes", type=int, default=8, help="scenes per (level, count)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--stages", action="store_true", help="per-stage table at the worst levels")
    parser.add_argument(
        "--methods",
        dest="configs",
        default="all",
        help="'all' (the presets and variants above, then every registered method) or a comma-separated list",
    )
    parser.add_argument(
        "--budget-s",
        type=float,
        default=None,
        help="seconds per method after its first chunk (slow methods then run on part of the scenes)",
    )
    parser.add_argument(
        "--quick", action="store_true", help="tiny run: paper() only, counts 8, 1 scene each"
    )
    parser.add_argument(
        "--figure", default=os.path.join("experiments", "figures", "robustness.png")
    )
    parser.add_argument("--json", default=None, help="also write the numbers here")
    args = parser.parse_args(argv)
    if args.quick:
        args.counts, args.scenes, args.configs = [8], 1, "paper"
    known = all_methods()
    names = (
        list(known)
        if args.configs == "all"
        else [n.strip() for n in args.configs.split(",") if n.strip()]
    )
    unknown = [n for n in names if n not in known]
    if unknown:
        parser.error(f"--methods: unknown {unknown}; known: {', '.join(known)}")
    out = run(
        counts=args.counts,
        scenes=args.scenes,
        seed=args.seed,
        stages=args.stages,
        configs=names,
        budget_s=args.budget_s,
    )
    os.makedirs(os.path.dirname(os.path.abspath(args.figure)), exist_ok=True)
    figure(out, args.figure)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)
    print(markdown_tables(out))
    print(
        f"\ntotal {out['total_seconds']:.1f} s; wrote {args.figure}"
        + (f" and {args.json}" if args.json else "")
    )
    return out


if __name__ == "__main__":
    main()
