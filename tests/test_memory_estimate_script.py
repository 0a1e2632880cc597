"""Smoke test: experiments/memory_estimate.py sets the estimate beside XLA's figure for the
program a library call compiles, one table row per preset and shape."""

import os
import re
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "experiments"))

import memory_estimate  # noqa: E402

import cdog_jax  # noqa: E402


def test_one_row_per_preset_and_shape_with_the_estimate_beside_xla(capsys):
    memory_estimate.main(["--presets", "paper", "--shapes", "3x16"])
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| `")]
    assert len(rows) == 1
    cells = [c.strip() for c in rows[0].strip("|").split("|")]
    assert cells[:2] == ["`paper()`", "3 × 16"]
    xla, estimate, ratio = (float(c) for c in cells[2:])
    expected = cdog_jax.estimate_peak_bytes(3, 16, cdog_jax.Config.paper()) / 48.0**2
    assert np.isclose(estimate, expected, atol=0.01)
    assert xla > 0 and np.isclose(ratio, estimate / xla, rtol=0.01)
    assert re.fullmatch(r"\d+\.\d\d", cells[4])
