"""Points in the plane of a ring of cameras: what each method groups there, and what the
validity gate's rule for degenerate geometry leaves (docs/ALGORITHM.md §12, rule 5).

Five cameras on a ring of radius 3 m, all at one height, look at the ring's centre (640×480,
f = 800 px); 30 points are drawn in a 1.2 m square at the cameras' height and then lifted by
up to ``lift`` metres (0: every point in the plane of the camera centres, where every
epipolar line of the scene is the same line). Detections have σ = 0.3 px. For each lift,
seed and method the script prints the valid groups that hold one point (right), those that
mix points (wrong, with their numbers of views) and the status.

    python experiments/degenerate_geometry.py
    python experiments/degenerate_geometry.py --seeds 5 --methods best paper greedy
"""

from __future__ import annotations

import argparse

import jax.numpy as jnp
import numpy as np

from cdog_jax import Rig, Status, associate

SLOTS = 64


def look_at(centre: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World-to-camera ``R (3, 3)``, ``t (3,)`` of a camera at ``centre`` looking at
    ``target`` (z forward, y down, the world's z up)."""
    z = target - centre
    z = z / np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ centre


def ring(num_views: int, rng: np.random.Generator) -> Rig:
    """Cameras on a ring of radius 3 in the plane z = 0, looking near the origin."""
    K, R, t = [], [], []
    for m in range(num_views):
        angle = 2 * np.pi * m / num_views + 0.2 * rng.standard_normal()
        centre = np.array([3 * np.cos(angle), 3 * np.sin(angle), 0.0])
        target = np.array([0.1 * rng.standard_normal(), 0.1 * rng.standard_normal(), 0.0])
        Rm, tm = look_at(centre, target)
        K.append([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
        R.append(Rm)
        t.append(tm)
    return Rig(*(jnp.asarray(np.array(a), jnp.float32) for a in (K, R, t)))


def scene(rig: Rig, X: np.ndarray, sigma: float, rng: np.random.Generator):
    """``xy (M, SLOTS, 2)``, ``mask (M, SLOTS)`` and the point of each slot (−1: none)."""
    K, R, t = (np.asarray(a, np.float64) for a in (rig.K, rig.R, rig.t))
    h = np.einsum("mij,mnj->mni", K, np.einsum("mij,nj->mni", R, X) + t[:, None, :])
    xy_true = h[..., :2] / h[..., 2:3]
    M = K.shape[0]
    xy = np.zeros((M, SLOTS, 2), np.float32)
    mask = np.zeros((M, SLOTS), bool)
    point = np.full((M, SLOTS), -1)
    for m in range(M):
        slots = rng.permutation(SLOTS)[: len(X)]
        xy[m, slots] = xy_true[m] + sigma * rng.standard_normal((len(X), 2))
        mask[m, slots] = True
        point[m, slots] = np.arange(len(X))
    return xy, mask, point


def right_and_wrong(result, point: np.ndarray) -> tuple[int, list[int]]:
    """The number of valid groups of one point, and the sizes of the others."""
    right, wrong = 0, []
    for row in np.asarray(result.groups)[np.asarray(result.valid)]:
        ids = {int(point[m, s]) for m, s in enumerate(row) if s >= 0}
        if len(ids) == 1:
            right += 1
        else:
            wrong.append(int(np.sum(row >= 0)))
    return right, sorted(wrong)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--lifts", type=float, nargs="+", default=[0.0, 0.01, 0.05, 0.3])
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--methods", nargs="+", default=["best", "paper", "greedy"])
    parser.add_argument("--sigma", type=float, default=0.3)
    args = parser.parse_args(argv)
    print("| lift (m) | seed | method | right | wrong (views of each) | flagged |")
    print("|---|---|---|---|---|---|")
    for lift in args.lifts:
        for seed in range(args.seeds):
            rng = np.random.default_rng(seed)
            rig = ring(5, rng)
            X = np.c_[rng.uniform(-0.6, 0.6, (30, 2)), lift * rng.uniform(-1, 1, 30)]
            xy, mask, point = scene(rig, X, args.sigma, rng)
            for method in args.methods:
                result = associate(rig, xy, mask, method=method, sigma=args.sigma)
                right, wrong = right_and_wrong(result, point)
                flagged = bool(int(result.status) & Status.AMBIGUOUS_GEOMETRY)
                print(
                    f"| {lift} | {seed} | {method} | {right} | {len(wrong)} {wrong or ''} "
                    f"| {'yes' if flagged else ''} |"
                )


if __name__ == "__main__":
    main()
