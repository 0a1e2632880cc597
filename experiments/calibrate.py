"""Camera refinement from associations on the built-in rig.

Question: starting from a drifted calibration (three levels of rotation, centre and focal
noise on every view), how well does alternating association and joint camera + point
refinement recover the rig, and does re-associating with the refined rig recover the
association quality? Runs ``cdog-jax calibrate`` (``cdog_jax/calibration/_drift_experiment.py``)
with all levels and writes the convergence figure.

Usage: ``python experiments/calibrate.py [--scenes 4] [--points 60] [--rounds 4]
[--out experiments/figures/calibration.png]``.
"""

from __future__ import annotations

import sys

from cdog_jax.cli import main

if __name__ == "__main__":
    argv = sys.argv[1:]
    if "--out" not in argv:
        argv += ["--out", "experiments/figures/calibration.png"]
    sys.exit(main(["calibrate", *argv]))
