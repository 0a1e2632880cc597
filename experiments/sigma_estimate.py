"""How well does ``sigma="auto"`` estimate the detection noise, and does it say when it
cannot?

Question: the ratio σ̂/σ (median and 10–90 % range over scenes) of the estimator in
:func:`cdog_jax.graph.estimate_sigma` against the previous one (half-normal + exponential EM on every
node's nearest epipolar distance, kept here as :func:`old_estimate_sigma`), and how often
the new one falls back, on

- ``grid``: the benchmark grid, σ ∈ {0.25, 1, 3, 5} × counts 5–130;
- ``robust``: the robustness levels at σ = 1 (drop rate 30 %; Poisson clutter 5 and 20 per
  view), counts 20, 60, 100;
- ``sparse``: 1–5 points at σ = 1, without and with 1–3 clutter detections per view;
- ``heavy``: σ = 1 with heavy-tailed noise (Student-t, 3 degrees of freedom, scaled to
  std σ; and a Gaussian where 10 % / 20 % of the detections get 20 σ noise instead);

plus the share of impure groups (members of different points or clutter) of
``Config.paper()`` with σ estimated against σ given on the sparse scenes with clutter, and
the noise-free one-point scene (the old estimator's NaN).

Method: built-in 10-camera rig, scenes from :func:`cdog_jax.synthetic.generate_scenes`
(heavy tails: drawn at σ = 0, then the noise is added here); each estimator runs over a
whole set in one compiled ``lax.map`` call.

Usage::

    python experiments/sigma_estimate.py [--scenes 4] [--quick] [--json out.json]

Prints Markdown tables.
"""

from __future__ import annotations

import argparse
import json
import time

import jax
import jax.numpy as jnp
import numpy as np

from cdog_jax import Config, associate_batch
from cdog_jax.geometry import epipolar_distances
from cdog_jax.graph import estimate_sigma
from cdog_jax.synthetic import default_rig, generate_scenes


def focal_length(K):
    """The rig's focal length (px) as the σ fit reads it: the median over views of
    ``(|f_x| + |f_y|) / 2``."""
    return jnp.median(0.5 * (jnp.abs(K[:, 0, 0]) + jnp.abs(K[:, 1, 1])))


GRID_SIGMAS = (0.25, 1.0, 3.0, 5.0)
GRID_COUNTS = (5, 10, 20, 40, 70, 100, 130)
ROBUST_LEVELS = (("drop 30 %", 0.3, 0.0), ("clutter 5", 0.0, 5.0), ("clutter 20", 0.0, 20.0))
ROBUST_COUNTS = (20, 60, 100)
ROBUST_CLUTTER_CAPACITY = 44
SPARSE_COUNTS = (1, 2, 3, 4, 5)
SPARSE_CLUTTER = (0.0, 1.0, 2.0, 3.0)
SPARSE_CLUTTER_CAPACITY = 10
HEAVY = (("Student-t ν=3", "t", 0.0), ("10 % at 20 σ", "mix", 0.1), ("20 % at 20 σ", "mix", 0.2))
HEAVY_COUNTS = (10, 40, 100)


def old_estimate_sigma(d, mask):
    """The previous estimator, unchanged: EM (30 iterations) on a half-normal + exponential
    mixture of every node's nearest distance, started from the median and the mean."""
    s = jnp.min(d, axis=-1)
    ok = jnp.isfinite(s)
    w_ok = ok.astype(d.dtype)
    n = jnp.sum(w_ok)
    x = jnp.where(ok, s, 0.0)
    tiny = jnp.finfo(d.dtype).tiny
    flat = jnp.where(ok, s, jnp.inf).reshape(-1)
    median = jnp.sort(flat)[jnp.maximum(n.astype(jnp.int32) - 1, 0) // 2]
    median = jnp.where(jnp.isfinite(median), median, 0.0)
    c0 = jnp.maximum(median, 1e-3)
    lam0 = 1.0 / jnp.maximum(jnp.sum(x) / jnp.maximum(n, 1.0), 1e-3)

    def em(_, state):
        c, lam, pi = state
        log_half_normal = 0.5 * jnp.log(2.0 / jnp.pi) - jnp.log(c) - 0.5 * (x / c) ** 2
        log_expo = jnp.log(lam) - lam * x
        resp = jax.nn.sigmoid(jnp.log(pi) + log_half_normal - jnp.log1p(-pi) - log_expo) * w_ok
        n1 = jnp.sum(resp)
        c = jnp.sqrt(jnp.sum(resp * x * x) / jnp.maximum(n1, tiny))
        lam = (n - n1) / jnp.maximum(jnp.sum((w_ok - resp) * x), tiny)
        pi = jnp.clip(n1 / jnp.maximum(n, 1.0), 1e-4, 1.0 - 1e-4)
        return jnp.maximum(c, 1e-6), jnp.maximum(lam, 1e-6), pi

    c, _, _ = jax.lax.fori_loop(0, 30, em, (c0, lam0, jnp.asarray(0.5, d.dtype)))
    return jnp.where(n > 0, c / jnp.sqrt(2.0), 0.0)


@jax.jit
def _estimates(rig, xy, mask):
    def one(args):
        d = epipolar_distances(rig, *args)
        new, fallback = estimate_sigma(d, args[1], focal_length(rig.K))
        return old_estimate_sigma(d, args[1]), new, fallback

    return jax.lax.map(one, (xy, mask), batch_size=8)


def estimate_both(rig, xy, mask):
    """``(old σ̂, new σ̂, new fallback)``, each ``(B,)``, for a batch of scenes. Scenes and
    slots are padded (empty) to multiples of 8 and 16 so that few shapes compile."""
    B, M, P = np.shape(mask)
    B2, P2 = -(-B // 8) * 8, -(-P // 16) * 16
    xy = jnp.pad(jnp.asarray(xy), ((0, B2 - B), (0, 0), (0, P2 - P), (0, 0)))
    mask = jnp.pad(jnp.asarray(mask), ((0, B2 - B), (0, 0), (0, P2 - P)))
    return tuple(np.asarray(a)[:B] for a in _estimates(rig, xy, mask))


def _scenes(rig, key, counts, sigma, capacity, drop=0.0, clutter=0.0, clutter_capacity=0):
    counts = np.asarray(counts)
    return generate_scenes(
        key,
        rig,
        jnp.asarray(counts, jnp.int32),
        jnp.full(counts.shape, sigma, jnp.float32),
        capacity=capacity,
        drop_rate=jnp.asarray(np.broadcast_to(drop, counts.shape), jnp.float32),
        clutter_rate=jnp.asarray(np.broadcast_to(clutter, counts.shape), jnp.float32),
        clutter_capacity=clutter_capacity,
    )


def _heavy_noise(key, batch, kind, share, sigma):
    """Detections of a σ = 0 batch with heavy-tailed noise added (padding and clutter too)."""
    k1, k2, k3 = jax.random.split(key, 3)
    shape = batch.xy.shape
    if kind == "t":
        nu = 3.0
        noise = sigma * jax.random.t(k1, nu, shape) / np.sqrt(nu / (nu - 2.0))  # std σ
    else:
        far = jax.random.bernoulli(k2, share, shape[:-1])[..., None]
        noise = sigma * jax.random.normal(k3, shape) * jnp.where(far, 20.0, 1.0)
    return jnp.where(batch.mask[..., None], batch.xy + noise, 0.0)


def _ratio_row(label, sigma_true, old, new, fallback):
    """σ̂/σ quantiles; after: over the scenes that did not fall back (the fallback share apart)."""
    r_old, r_new = old / sigma_true, new[~fallback] / sigma_true
    q = lambda r: (
        (float(np.median(r)), float(np.quantile(r, 0.1)), float(np.quantile(r, 0.9)))
        if r.size
        else (np.nan,) * 3
    )
    return {
        "set": label,
        "scenes": int(old.size),
        "old": q(r_old),
        "new": q(r_new),
        "old_nonfinite": int(np.sum(~np.isfinite(old))),
        "fallback": float(np.mean(fallback)),
    }


def _impure_share(labels, instance, mask):
    """Share of predicted groups (over all scenes) whose members are not all one true point."""
    impure = total = 0
    for lab, ins, m in zip(labels, instance, mask):
        for g in np.unique(lab[m & (lab >= 0)]):
            ids = ins[lab == g]
            total += 1
            impure += int(np.any(ids < 0) or np.unique(ids).size > 1)
    return impure, total


def _purity(rig, batch, old, with_clutter):
    """Impure groups ``(impure, total)`` of ``Config.paper()`` on the scenes ``with_clutter``,
    with σ from the old estimator, σ="auto" and σ = 1 given."""
    purity = {}
    sub = jax.tree.map(lambda a: a[with_clutter], batch)
    # The old estimator's pipeline is the given-σ pipeline with σ = its estimate.
    for name, sigma in (
        ("before", jnp.asarray(old[with_clutter], jnp.float32)),
        ("auto", "auto"),
        ("given", 1.0),
    ):
        res = associate_batch(
            rig, sub.xy, sub.mask, method=Config.paper(), sigma=sigma, batch_size=8
        )
        purity[name] = _impure_share(
            np.asarray(res.labels), np.asarray(sub.instance), np.asarray(sub.mask)
        )
    purity["scenes"] = int(with_clutter.sum())
    return purity


def run(*, scenes=4, seed=0, quick=False, log=print):
    rig = default_rig()
    key = jax.random.PRNGKey(seed)
    grid_counts = GRID_COUNTS[:1] if quick else GRID_COUNTS
    rows, t0 = [], time.perf_counter()

    # (a) the benchmark grid: one batch per σ.
    for i, sigma in enumerate(GRID_SIGMAS[1::2] if quick else GRID_SIGMAS):
        counts = np.repeat(grid_counts, scenes)
        batch = _scenes(rig, jax.random.fold_in(key, i), counts, sigma, max(grid_counts))
        old, new, fb = estimate_both(rig, batch.xy, batch.mask)
        for c in grid_counts:
            at = counts == c
            rows.append(_ratio_row(f"grid σ={sigma:g} n={c}", sigma, old[at], new[at], fb[at]))
    log(f"grid: {time.perf_counter() - t0:.0f} s")

    # (b) the robustness levels at σ = 1.
    robust_counts, robust_capacity = (
        ((5,), 11) if quick else (ROBUST_COUNTS, ROBUST_CLUTTER_CAPACITY)
    )
    for i, (label, drop, clutter) in enumerate(ROBUST_LEVELS):
        counts = np.repeat(robust_counts, scenes)
        batch = _scenes(
            rig,
            jax.random.fold_in(key, 100 + i),
            counts,
            1.0,
            max(robust_counts),
            drop,
            clutter,
            robust_capacity,
        )
        old, new, fb = estimate_both(rig, batch.xy, batch.mask)
        rows.append(_ratio_row(f"robust {label}", 1.0, old, new, fb))
    log(f"robust: {time.perf_counter() - t0:.0f} s")

    # (c) sparse scenes, with and without clutter; purity with σ estimated and given.
    sparse_scenes = scenes if quick else 10 * scenes
    sparse_counts, sparse_clutter = (
        (SPARSE_COUNTS[:2], SPARSE_CLUTTER[::2]) if quick else (SPARSE_COUNTS, SPARSE_CLUTTER)
    )
    counts = np.tile(np.repeat(sparse_counts, sparse_scenes), len(sparse_clutter))
    clutter = np.repeat(sparse_clutter, len(sparse_counts) * sparse_scenes)
    batch = _scenes(
        rig,
        jax.random.fold_in(key, 200),
        counts,
        1.0,
        max(SPARSE_COUNTS),
        0.0,
        clutter,
        SPARSE_CLUTTER_CAPACITY,
    )
    old, new, fb = estimate_both(rig, batch.xy, batch.mask)
    for c in sparse_clutter:
        at = clutter == c
        rows.append(_ratio_row(f"sparse 1–5 points, clutter {c:g}", 1.0, old[at], new[at], fb[at]))
    purity = {} if quick else _purity(rig, batch, old, clutter > 0)
    log(f"sparse: {time.perf_counter() - t0:.0f} s")

    # (d) heavy-tailed noise at σ = 1.
    heavy_counts = grid_counts if quick else HEAVY_COUNTS  # --quick: the grid's scene shape
    for i, (label, kind, share) in enumerate(HEAVY[1:] if quick else HEAVY):
        counts = np.repeat(heavy_counts, scenes)
        batch = _scenes(rig, jax.random.fold_in(key, 300 + i), counts, 0.0, max(heavy_counts))
        xy = _heavy_noise(jax.random.fold_in(key, 400 + i), batch, kind, share, 1.0)
        old, new, fb = estimate_both(rig, xy, batch.mask)
        rows.append(_ratio_row(f"heavy {label}", 1.0, old, new, fb))
    log(f"heavy: {time.perf_counter() - t0:.0f} s")

    # The noise-free one-point scene (--quick: in the grid's scene shape).
    batch = _scenes(
        rig,
        jax.random.fold_in(key, 500),
        np.ones(scenes, int),
        0.0,
        max(grid_counts) if quick else 1,
    )
    old, new, fb = estimate_both(rig, batch.xy, batch.mask)
    noise_free = {
        "old": [float(v) for v in old],
        "new": [float(v) for v in new],
        "fallback": [bool(v) for v in fb],
    }
    # The same with every distance exactly 0 (one point in three views, exact arithmetic).
    d = jnp.where(jnp.eye(3, dtype=bool)[:, None, :, None], jnp.inf, jnp.zeros((3, 1, 3, 1)))
    both = jax.jit(
        lambda d, mask: (old_estimate_sigma(d, mask), *estimate_sigma(d, mask, focal_length(rig.K)))
    )
    old, new, fb = (np.asarray(a) for a in both(d, jnp.ones((3, 1), bool)))
    noise_free["exact_zero"] = {"old": float(old), "new": float(new), "fallback": bool(fb)}
    return {
        "rows": rows,
        "purity": purity,
        "noise_free_one_point": noise_free,
        "scenes_per_cell": scenes,
        "seed": seed,
        "seconds": time.perf_counter() - t0,
    }


def markdown(out):
    lines = [
        "| scenes | n | σ̂/σ, simple EM: median [10 %, 90 %] "
        '| `sigma="auto"` (scenes not falling back) | `sigma="auto"`: fallback share |',
        "|---|---|---|---|---|",
    ]
    fmt = lambda q: f"{q[0]:.2f} [{q[1]:.2f}, {q[2]:.2f}]"
    for r in out["rows"]:
        bad = f" ({r['old_nonfinite']} not finite)" if r["old_nonfinite"] else ""
        lines.append(
            f"| {r['set']} | {r['scenes']} | {fmt(r['old'])}{bad} | {fmt(r['new'])} | {r['fallback']:.2f} |"
        )
    p = out["purity"]
    lines += (
        []
        if not p
        else [
            "",
            f"Sparse scenes with clutter ({p['scenes']} scenes), Config.paper(): impure groups "
            f"{p['before'][0]} of {p['before'][1]} with σ from the simple EM, "
            f"{p['auto'][0]} of {p['auto'][1]} with sigma='auto', "
            f"{p['given'][0]} of {p['given'][1]} with σ = 1 given.",
        ]
    )
    nf = out["noise_free_one_point"]
    ez = nf["exact_zero"]
    lines.append(
        "Noise-free one-point scenes: simple EM σ̂ = "
        f"{', '.join(f'{v:.1e}' for v in nf['old'])} px, "
        "sigma='auto' "
        f"{', '.join(f'{v:.1e}' for v in nf['new'])} px (fallback {sum(nf['fallback'])} of {len(nf['new'])}); "
        f"every distance exactly 0: simple EM {ez['old']}, sigma='auto' {ez['new']:.1e} px "
        f"(fallback {ez['fallback']})."
    )
    return "\n".join(lines)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenes", type=int, default=4, help="scenes per cell (sparse: 10× that)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quick", action="store_true", help="a tiny grid (smoke test)")
    p.add_argument("--json", default=None, help="also write the numbers here")
    args = p.parse_args(argv)
    out = run(scenes=args.scenes, seed=args.seed, quick=args.quick)
    print(markdown(out))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)
    return out


if __name__ == "__main__":
    main()
