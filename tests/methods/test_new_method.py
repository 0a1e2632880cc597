"""A method written in one module (``mutual_nn_method.py``, registered on import) goes
through every entry point by its name, with no other file changed: ``associate``,
``associate_batch``, ``sweep``, ``cdog-jax associate --method`` and
``cdog-jax benchmark --methods``."""

from __future__ import annotations

import json

import mutual_nn_method  # noqa: F401  (registers "mutual_nn")
import numpy as np
import pytest
from helpers import random_scene, ring_rig

from cdog_jax import Config, associate, method_from, method_names
from cdog_jax.benchmark import Grid, sweep
from cdog_jax.cli import main
from cdog_jax.io import save_detections_json, save_rig

RIG = ring_rig(4)


def test_registered_by_name_and_usable_from_the_api():
    assert "mutual_nn" in method_names()
    method = method_from("mutual_nn", "test")
    assert method == mutual_nn_method.MutualNearest() and method.name == "mutual_nn"
    xy, mask, inst, _ = random_scene(RIG, 4, 8, seed=103)
    res = associate(RIG, xy.astype(np.float32), mask, method="mutual_nn", sigma=0.0)
    assert int(res.num_groups) == len({int(i) for i in inst[mask] if (inst == i).sum() >= 2})


def test_sweep_runs_it_beside_cdog():
    grid = Grid(sigmas=(0.0, 2.0), counts=(4,), scenes=1, views=(0, 1, 2, 3))
    from cdog_jax.synthetic import default_rig

    result = sweep(
        default_rig(),
        grid,
        methods=["mutual_nn", "paper"],
        buckets=(8,),
        timing=False,
        progress=False,
    )
    assert result.configs == ("mutual_nn", "paper")
    assert result.metrics["mutual_nn"]["pg_f1"].shape == (2,)
    assert result.metrics["mutual_nn"]["pg_f1"][0] == pytest.approx(1.0)
    # numbers are traced: changing them compiles nothing new
    changed = {
        "mutual_nn": mutual_nn_method.MutualNearest(alpha_tau=3.0),
        "paper": Config.paper(delta=0.6),
    }
    again = sweep(default_rig(), grid, methods=changed, buckets=(8,), timing=False, progress=False)
    assert again.compile_s == 0.0


def test_commands_take_it_by_name(tmp_path, capsys):
    xy, mask, _, _ = random_scene(RIG, 4, 8, seed=103)
    save_rig(tmp_path / "rig.json", RIG, format="json", image_size=(640, 480))
    save_detections_json(tmp_path / "points.json", xy, mask)
    out = tmp_path / "groups.json"
    argv = [
        "associate",
        "--rig",
        str(tmp_path / "rig.json"),
        "--points",
        str(tmp_path / "points.json"),
    ]
    assert main([*argv, "--method", "mutual_nn", "--sigma", "0", "--out", str(out)]) == 0
    assert "Associated with mutual_nn" in capsys.readouterr().out
    assert len(json.loads(out.read_text())["groups"]) == 4

    bench = tmp_path / "bench"
    argv = [
        "benchmark",
        "--quick",
        "--sigmas",
        "0",
        "--counts",
        "4",
        "--scenes",
        "1",
        "--views",
        "0",
        "1",
        "2",
        "3",
    ]
    assert (
        main(
            [
                *argv,
                "--methods",
                "mutual_nn,paper",
                "--no-figures",
                "--no-timing",
                "--out",
                str(bench),
            ]
        )
        == 0
    )
    assert "| 0 | mutual_nn |" in capsys.readouterr().out
