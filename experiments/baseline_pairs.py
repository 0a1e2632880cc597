"""Pairwise precision and recall of the epipolar baselines, and their warm time per scene.

Question: how well do greedy matching, CCA and triangulation voting group same-point
detections at σ = 0, 1, 3 px, next to C-DOG's default preset, and how long does each take
on one scene? A pair of detections is a true pair when both come from one point; scores
are pooled over all scenes. Usage: ``python experiments/baseline_pairs.py [--scenes 20]
[--views 10] [--points 30]``.
"""

from __future__ import annotations

import argparse
import math
import time

import jax
import jax.numpy as jnp
import numpy as np

import cdog_jax
from cdog_jax.baselines import Components, Greedy, Voting
from cdog_jax.geometry import epipolar_distances
from cdog_jax.synthetic import default_rig, generate_scene

METHODS = {"greedy (K=2)": Greedy(), "CCA": Components(), "voting": Voting()}


def method_fn(method):
    """One scene, as a method wrapper runs it: distances, gate, then the method's groups."""

    def run(rig, xy, mask, sigma):
        d = epipolar_distances(rig, xy, mask)
        tau = jnp.maximum(2.0 * math.sqrt(2.0) * sigma, 1.0).astype(xy.dtype)
        return method.group_table(
            rig, xy, mask, d, sigma, tau, method.thresholds(sigma, dtype=xy.dtype)
        )

    return jax.jit(run)


def labels_of(groups, valid, num_slots):
    """``(M, P)`` group id of every detection (-1: none), from a group table."""
    groups, valid = np.asarray(groups), np.asarray(valid)
    labels = np.full((groups.shape[1], num_slots), -1)
    for g in np.flatnonzero(valid):
        for m, s in enumerate(groups[g]):
            if s >= 0:
                labels[m, s] = g
    return labels


def pair_counts(labels, instance, mask):
    """``(true pairs found, pairs found, true pairs)`` over detection pairs of one scene."""
    lab = np.where(mask, labels, -1).reshape(-1)
    inst = np.where(mask, instance, -1).reshape(-1)
    upper = np.triu(np.ones((lab.size, lab.size), bool), 1)
    found = (lab[:, None] == lab[None, :]) & (lab[:, None] >= 0) & upper
    true = (inst[:, None] == inst[None, :]) & (inst[:, None] >= 0) & upper
    return int(np.sum(found & true)), int(np.sum(found)), int(np.sum(true))


def accuracy(sigmas, scenes, views, points, capacity):
    rig = default_rig(num_views=views)
    fns = {name: method_fn(m) for name, m in METHODS.items()}
    rows = []
    for sigma in sigmas:
        totals = {name: np.zeros(3, int) for name in [*fns, "C-DOG extended()"]}
        for seed in range(scenes):
            s = generate_scene(jax.random.PRNGKey(seed), rig, points, sigma, capacity=capacity)
            for name, f in fns.items():
                g, v, _ = f(rig, s.xy, s.mask, jnp.float32(sigma))
                totals[name] += pair_counts(
                    labels_of(g, v, capacity), np.asarray(s.instance), np.asarray(s.mask)
                )
            result = cdog_jax.associate(rig, s.xy, s.mask, sigma=max(sigma, 1e-3))
            totals["C-DOG extended()"] += pair_counts(
                np.asarray(result.labels), np.asarray(s.instance), np.asarray(s.mask)
            )
        for name, (hit, found, true) in totals.items():
            rows.append((name, sigma, hit / max(found, 1), hit / max(true, 1)))
    return rows


def timing(views, points, capacity, repeats):
    rig = default_rig(num_views=views)
    scenes = [
        generate_scene(jax.random.PRNGKey(1000 + k), rig, points, 1.0, capacity=capacity)
        for k in range(repeats)
    ]
    out = {}
    for name, m in METHODS.items():
        f = method_fn(m)
        jax.block_until_ready(f(rig, scenes[0].xy, scenes[0].mask, jnp.float32(1.0)))  # compile
        times = []
        for s in scenes:
            t0 = time.perf_counter()
            jax.block_until_ready(f(rig, s.xy, s.mask, jnp.float32(1.0)))
            times.append(time.perf_counter() - t0)
        out[name] = float(np.median(times))
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", type=int, default=20)
    parser.add_argument("--views", type=int, default=10)
    parser.add_argument("--points", type=int, default=30)
    parser.add_argument("--time-points", type=int, default=50)
    args = parser.parse_args()
    capacity = max(32, 1 << (args.points - 1).bit_length())
    print(
        f"pairwise precision / recall, {args.scenes} scenes of {args.views} views x {args.points} points (P = {capacity})"
    )
    print("| method | σ = 0 | σ = 1 | σ = 3 |\n|---|---|---|---|")
    rows = accuracy((0.0, 1.0, 3.0), args.scenes, args.views, args.points, capacity)
    for name in dict.fromkeys(r[0] for r in rows):
        cells = [f"{p:.3f} / {r:.3f}" for n, _, p, r in rows if n == name]
        print(f"| {name} | " + " | ".join(cells) + " |")
    t_capacity = max(32, 1 << (args.time_points - 1).bit_length())
    print(
        f"\nwarm time per scene (median of 10, compile apart), {args.views} views x {args.time_points} points (P = {t_capacity}):"
    )
    for name, seconds in timing(args.views, args.time_points, t_capacity, 10).items():
        print(f"| {name} | {1e3 * seconds:.1f} ms |")


if __name__ == "__main__":
    main()
