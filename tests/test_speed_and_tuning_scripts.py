"""Smoke tests: experiments/bench_speed.py and experiments/tune_thresholds.py run on tiny
inputs and report what they claim to."""

import importlib.util
import os

import numpy as np

from cdog_jax import Config
from cdog_jax.benchmark import Grid

HERE = os.path.dirname(__file__)


def _load(name):
    spec = importlib.util.spec_from_file_location(
        name, os.path.join(HERE, "..", "experiments", f"{name}.py")
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_bench_speed_quick_grid_in_a_fresh_process(capsys):
    module = _load("bench_speed")
    module.main(["--quick", "--runs", "1", "--warm", "1", "--skip-single", "--cpu-devices", "1,2"])
    text = capsys.readouterr().out
    head = "| grid (24 scenes) | cpu: 1 × cpu (1 process), median of 1 | cpu: 2 × cpu (1 process), median of 1 |"
    assert head in text, text
    for row in (
        "| cold call (trace + compile + run) |",
        "| warm call |",
        "| peak RSS |",
        "scenes/s",
    ):
        assert row in text, row
    # The scenes sharded over two CPU devices score exactly as on one.
    f1_row = next(line for line in text.splitlines() if line.startswith("| mean PG-F1"))
    one, two = f1_row.split(" | ")[1:3]
    assert one == two and one.startswith("paper 0."), f1_row


def test_bench_speed_single_scene_rows():
    rows = _load("bench_speed").single_scene(["paper"], counts=(5,), runs=1)
    assert len(rows) == 1 and rows[0][:2] == ("paper", 5)
    assert rows[0][2] > 0 and 0 < rows[0][3] < 5.0  # compile > 0 s, warm call well under 5 s


def test_tuning_search_ranks_every_combination(capsys):
    module = _load("tune_thresholds")
    grid = Grid(sigmas=(1.0,), counts=(6,), scenes=2, seed=1, views=(0, 1, 2, 3), capacity=8)
    best, rows = module.search(
        {"delta": (0.3, 0.5), "alpha_tau": (2.0, 3.0)}, Config.paper(), grid, (8,), top=2
    )
    assert len(rows) == 4 and [r[0] for r in rows] == sorted((r[0] for r in rows), reverse=True)
    assert (best.delta, best.alpha_tau) == (rows[0][1]["delta"], rows[0][1]["alpha_tau"])
    assert all(0.0 <= r[0] <= 1.0 for r in rows)
    assert "the starting values {'delta': 0.5, 'alpha_tau': 2.0}" in capsys.readouterr().out
    assert (
        module.objective({"pg_f1": np.ones(3), "mp_f1": np.ones(3), "g_f1": np.zeros(3)}) == 2 / 3
    )
