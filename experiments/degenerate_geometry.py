"""Points in the plane of a ring of cameras: what each method groups there, and what the
validity gate's rule for degenerate geometry leaves (docs/ALGORITHM.md §12, rule 5).

Five cameras evenly on a ring of radius 3 m, all at one height, look at the ring's centre
(``cdog_jax.synthetic.ring_rig``; 640×480, f = 800 px); 30 points are drawn in a 1.2 m square at the cameras' height and then lifted by
up to ``lift`` metres (0: every point in the plane of the camera centres, where every
epipolar line of the scene is the same line). Detections have σ = 0.3 px. For each lift,
seed and method the script prints the valid groups that hold one point (right), those that
mix points (wrong, with their numbers of views) and the status.

    python experiments/degenerate_geometry.py
    python experiments/degenerate_geometry.py --seeds 5 --methods best paper greedy
"""

from __future__ import annotations

import argparse

import numpy as np

from cdog_jax import Rig, Status, associate
from cdog_jax.synthetic import ring_rig

SLOTS = 64


def ring() -> Rig:
    """Five cameras evenly on a ring of radius 3 m in the plane z = 0, looking at its centre."""
    return ring_rig(
        num_views=5,
        radius=3.0,
        height=0.0,
        target_height=0.0,
        focal_px=800.0,
        image_size=(640, 480),
    )


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
            rig = ring()
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
