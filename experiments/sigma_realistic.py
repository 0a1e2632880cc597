"""How close are the σ estimators (``sigma_mode`` ``"auto"`` and ``"robust"``) to the true noise
scale on realistic detections?

Question: σ̂/σ (median over scenes or frames) of the estimator on the levels of
``experiments/robustness_realistic.py`` (box and skeleton families, one factor at a time:
Student-t tails, far-off share, per-view spread, calibration error, clutter, doubles) and on
its target scenes (3–5 people, 5 views, ν = 2.5, σ = 5.21 px, the tails of real OpenPose
detections). σ is the scale the noise was drawn with: the Gaussian σ of the same median
absolute deviation per coordinate (``cdog_jax.synthetic.Realism``).

Method: the scenes of ``robustness_realistic.py`` (same seeds); box: σ̂ of each scene
(``estimate_sigma`` / ``estimate_sigma_robust``); skeleton: one σ̂ per frame, pooled over the
frame's joint classes as ``associate_classes`` does (``class_sigmas``). Only the estimator
runs (no association).

Usage::

    python experiments/sigma_realistic.py [--scenes 10] [--sequences 3] [--frames 5] [--estimator auto robust] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import robustness_realistic as rr  # noqa: E402

from cdog_jax import class_sigmas  # noqa: E402
from cdog_jax.geometry import epipolar_distances  # noqa: E402
from cdog_jax.graph import estimate_sigma, estimate_sigma_robust  # noqa: E402


def focal_length(K):
    """The rig's focal length (px) as the σ fit reads it: the median over views of
    ``(|f_x| + |f_y|) / 2``."""
    return jnp.median(0.5 * (jnp.abs(K[:, 0, 0]) + jnp.abs(K[:, 1, 1])))


ESTIMATORS = {"auto": estimate_sigma, "robust": estimate_sigma_robust}


@partial(jax.jit, static_argnames=("estimator",))
def _box_sigmas(rig, xy, mask, estimator):
    fit = ESTIMATORS[estimator]
    return jax.lax.map(
        lambda a: fit(epipolar_distances(rig, *a), a[1], focal_length(rig.K))[0],
        (xy, mask),
        batch_size=8,
    )


def _frame_sigmas(rig, frames, estimator):
    return class_sigmas(
        rig,
        np.asarray(frames.xy),
        np.asarray(frames.mask),
        np.asarray(frames.class_id),
        estimator=estimator,
    )


def run(scenes=10, sequences=3, frames=5, seed=rr.SEED, estimator="robust", log=print):
    t0 = time.perf_counter()
    out = {"estimator": estimator}
    for name, family in rr.FAMILIES.items():
        lv = rr.levels(family)
        if name == "box":
            rig, batch = rr.box_batch(lv, scenes, family, seed, False)
            ratio = np.asarray(_box_sigmas(rig, batch.xy, batch.mask, estimator)) / family["sigma"]
            per = scenes
        else:
            rig, batch = rr.skeleton_batch(lv, sequences, frames, family, seed)
            ratio = _frame_sigmas(rig, batch, estimator) / family["sigma"]
            per = sequences * frames
        out[name] = [
            {
                "factor": f,
                "value": v,
                "ratio": float(np.median(ratio[i * per : (i + 1) * per])),
                "p10": float(np.quantile(ratio[i * per : (i + 1) * per], 0.1)),
                "p90": float(np.quantile(ratio[i * per : (i + 1) * per], 0.9)),
            }
            for i, (f, v) in enumerate(lv)
        ]
        log(f"{name}: {time.perf_counter() - t0:.0f} s")
    fam = dict(rr.FAMILIES["skeleton"], sigma=5.21)
    rig, batch = rr.skeleton_batch(
        [("tails", 2.5)], 4 * sequences, frames, fam, seed + 11, people=(3, 4, 5)
    )
    ratio = _frame_sigmas(rig, batch, estimator) / fam["sigma"]
    out["targets"] = {
        "ratio": float(np.median(ratio)),
        "p10": float(np.quantile(ratio, 0.1)),
        "p90": float(np.quantile(ratio, 0.9)),
        "frames": int(ratio.size),
    }
    out["seconds"] = time.perf_counter() - t0
    return out


def markdown(out):
    lines = [
        f"σ estimator: sigma_mode={out['estimator']!r}",
        "",
        "| level | box σ̂/σ: median [10 %, 90 %] | skeleton σ̂/σ |",
        "|---|---|---|",
    ]
    fmt = lambda r: f"{r['ratio']:.2f} [{r['p10']:.2f}, {r['p90']:.2f}]"
    for b, s in zip(out["box"], out["skeleton"]):
        label = (
            rr._fmt_level(b["factor"], b["value"])
            if b["factor"] != "clutter"
            else f"clutter {b['value']:g} / {s['value']:g}"
        )
        lines.append(f"| {label} | {fmt(b)} | {fmt(s)} |")
    t = out["targets"]
    lines.append(
        f"| targets (ν = 2.5, σ = 5.21 px, 3–5 people, {t['frames']} frames) | | {fmt(t)} |"
    )
    return "\n".join(lines)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenes", type=int, default=10)
    p.add_argument("--sequences", type=int, default=3)
    p.add_argument("--frames", type=int, default=5)
    p.add_argument("--estimator", nargs="+", choices=tuple(ESTIMATORS), default=["auto", "robust"])
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    outs = []
    for estimator in args.estimator:
        out = run(args.scenes, args.sequences, args.frames, estimator=estimator)
        print(markdown(out))
        print(f"\n{out['seconds']:.0f} s\n")
        outs.append(out)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(outs, f, indent=1)


if __name__ == "__main__":
    main()
