"""The benchmark sweep: grid keys, one-call sweep vs per-scene calls, bucketing, sharding
over 4 CPU devices (subprocess), saving and loading. Tiny grids, 5 views, capacity 16."""

import csv
import dataclasses
import json
import os
import subprocess
import sys
import textwrap

import jax
import numpy as np
import pytest

from cdog_jax import Config, associate
from cdog_jax.benchmark import Grid, load_results, save_results, summary_table, sweep
from cdog_jax.benchmark._grid import compact_scene
from cdog_jax.metrics import scene_metrics
from cdog_jax.synthetic import default_rig, generate_scene

GRID = Grid(
    sigmas=(0.5, 3.0), counts=(3, 7, 12), scenes=2, seed=3, views=(0, 1, 2, 3, 4), capacity=16
)
# Same structure, other numbers: the sweep runs both through one pipeline mapped over
# thresholds, per-scene calls run them one by one.
CONFIGS = {"paper": Config.paper(), "loose": Config.paper(delta=0.3, alpha_tau=3.0)}
BATCH = 2
_CONTINUOUS = ("err3d", "bpe_px", "sigma_px_used")  # scene units, pixels


@pytest.fixture(scope="module")
def rig():
    return default_rig()


_SHARDED = """
import sys
import jax
jax.config.update("jax_numpy_rank_promotion", "raise")
jax.config.update("jax_numpy_dtype_promotion", "strict")
from cdog_jax import Config
from cdog_jax.benchmark import Grid, print_progress, save_results, sweep
from cdog_jax.synthetic import default_rig
assert jax.device_count() == 4, jax.devices()
result = sweep(
    default_rig(), {grid!r}, methods={configs!r}, buckets=(16,), batch_size={batch}, timing=False,
    progress=print_progress,
)
save_results(result, sys.argv[1])
try:  # refinement's solver cannot be split over devices: refused before compiling
    sweep(default_rig(), {grid!r}, methods={{"refine": Config.paper(refine=True)}}, buckets=(16,), timing=False)
except ValueError as error:
    print("refused:", error, file=sys.stderr)
"""


@pytest.fixture(scope="module")
def sharded_run(tmp_path_factory):
    """The sweep of ``padded`` on 4 CPU devices, in a subprocess (the device count must be
    set before jax starts); started early so that it compiles while this process does."""
    out = tmp_path_factory.mktemp("sharded")
    code = textwrap.dedent(_SHARDED).format(grid=GRID, configs=CONFIGS, batch=BATCH)
    flags = f"{os.environ.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count=4".strip()
    env = dict(os.environ, XLA_FLAGS=flags, JAX_PLATFORMS="cpu")
    with open(out / "stderr.txt", "w") as err:
        proc = subprocess.Popen(
            [sys.executable, "-c", code, str(out / "results")], env=env, stdout=err, stderr=err
        )
    yield proc, out
    if proc.poll() is None:
        proc.kill()
        proc.wait()


@pytest.fixture(scope="module")
def padded(rig, sharded_run):
    """Every scene padded to 16 slots (one bucket), with time estimates."""
    return sweep(
        rig, GRID, methods=CONFIGS, buckets=(16,), batch_size=BATCH, timing=True, timing_runs=1
    )


def _assert_same_metrics(a, b, *, exact):
    """Equal metrics; with ``exact=False`` the continuous ones (means of float32 distances)
    may differ by rounding, as they do when the slot capacity changes the reduction shapes."""
    assert a.configs == b.configs
    for name in a.configs:
        for field, value in a.metrics[name].items():
            msg = f"{name}.{field}"
            if exact or field not in _CONTINUOUS:
                np.testing.assert_array_equal(value, b.metrics[name][field], err_msg=msg)
            else:
                np.testing.assert_allclose(
                    value, b.metrics[name][field], rtol=1e-5, atol=1e-6, err_msg=msg
                )


def test_paper_grid_size_and_order():
    grid = Grid.paper()
    idx = grid.flat()
    assert grid.num_scenes == 4410 == idx.sigma.shape[0]
    assert len(grid.sigmas) == 21 and len(grid.counts) == 42
    assert int(idx.count[idx.sigma == 0.0].sum()) == 9575  # 3D points per σ (docs/BENCHMARK.md §1)
    np.testing.assert_array_equal(idx.cell, idx.sigma_index * 42 + idx.count_index)
    assert hash(grid) == hash(Grid.paper())


def test_scene_keys_do_not_depend_on_other_cells():
    full = Grid.paper()
    sub = Grid.paper(sigmas=(3.0, 1.0), counts=(130, 7), scenes=3)
    keys_full, keys_sub = np.asarray(full.keys()), np.asarray(sub.keys())
    assert len({k.tobytes() for k in keys_full}) == full.num_scenes  # all distinct
    at = {(s, c, k): i for i, (s, c, k) in enumerate(zip(*full.flat()[:3]))}
    for j, (s, c, k) in enumerate(zip(*sub.flat()[:3])):
        np.testing.assert_array_equal(keys_sub[j], keys_full[at[(s, c, k)]])
    assert not np.array_equal(np.asarray(full.replace(seed=1).keys()), keys_full)


def test_compact_scene_keeps_every_detection(rig, getkey):
    scene = generate_scene(getkey(), rig, 9, 1.0, capacity=16)
    small = compact_scene(scene, capacity=9)
    assert small.xy.shape == (10, 9, 2) and small.points3d.shape == (9, 3)
    scene, small = jax.device_get((scene, small))
    np.testing.assert_array_equal(small.points3d, scene.points3d[:9])
    for m in range(10):
        before = {
            (i, *p) for i, p in zip(scene.instance[m].tolist(), scene.xy[m].tolist()) if i >= 0
        }
        after = {
            (i, *p) for i, p in zip(small.instance[m].tolist(), small.xy[m].tolist()) if i >= 0
        }
        assert before == after
        n = int(scene.mask[m].sum())
        assert small.mask[m, :n].all() and not small.mask[m, n:].any()


def test_sweep_equals_per_scene_calls(rig, padded):
    sub = rig.select(GRID.views)
    idx, keys = GRID.flat(), GRID.keys()
    score = jax.jit(scene_metrics)
    for i in range(GRID.num_scenes):
        scene = generate_scene(
            keys[i], sub, int(idx.count[i]), float(idx.sigma[i]), capacity=GRID.capacity
        )
        scene = compact_scene(scene, capacity=16)
        assert int(scene.num_points) == padded.num_points[i]
        for name, config in CONFIGS.items():
            res = associate(sub, scene.xy, scene.mask, method=config, sigma=float(idx.sigma[i]))
            m = score(sub, res, scene)
            for field, value in padded.metrics[name].items():
                if not hasattr(m, field):
                    continue
                msg = f"scene {i} {name}.{field}"
                if field in _CONTINUOUS:  # float32 DLT: batched and single differ in rounding
                    expected = np.asarray(getattr(m, field))
                    np.testing.assert_allclose(
                        value[i], expected, rtol=1e-3, atol=1e-4, err_msg=msg
                    )
                else:  # counts and ratios of counts: every decision must agree
                    np.testing.assert_array_equal(
                        value[i], np.asarray(getattr(m, field)), err_msg=msg
                    )
            assert padded.metrics[name]["num_groups"][i] == int(res.num_groups)
    assert padded.metrics["paper"]["pg_f1"].mean() > 0.5  # the scenes are not trivial or empty
    assert np.all(padded.time_s["paper"] > 0) and padded.num_devices == 1


def test_bucketed_equals_padded_to_max(rig, padded):
    # batch 1: the plain-scan path (the CPU default), against the vmapped one of `padded`.
    events = []
    bucketed = sweep(
        rig,
        GRID,
        methods=CONFIGS,
        buckets=(8, 16),
        batch_size=1,
        timing=False,
        progress=events.append,
    )
    # One report per bucket, in bucket order as each finishes, counting the scenes done.
    assert [(e.bucket, e.capacity, e.num_buckets) for e in events] == [(0, 8, 2), (1, 16, 2)]
    assert [e.scenes_done for e in events] == [int(np.sum(bucketed.capacity == 8)), GRID.num_scenes]
    assert events[0].elapsed_s <= events[1].elapsed_s
    np.testing.assert_array_equal(bucketed.capacity, np.where(GRID.flat().count <= 8, 8, 16))
    np.testing.assert_array_equal(bucketed.num_points, padded.num_points)
    _assert_same_metrics(bucketed, padded, exact=False)
    assert np.isnan(bucketed.time_s["paper"]).all()
    # Progress is reported from the host between the bucket programs: without it, the same
    # programs run (none compiled again), with the same results.
    quiet = sweep(
        rig, GRID, methods=CONFIGS, buckets=(8, 16), batch_size=1, timing=False, progress=None
    )
    assert quiet.compile_s == 0.0
    for name in CONFIGS:
        for field, value in bucketed.metrics[name].items():
            np.testing.assert_array_equal(
                quiet.metrics[name][field], value, err_msg=f"{name}.{field}"
            )


def test_sharded_equals_unsharded(padded, sharded_run):
    proc, out = sharded_run
    assert proc.wait(timeout=300) == 0, (out / "stderr.txt").read_text()[-3000:]
    sharded = load_results(out / "results")
    log = (out / "stderr.txt").read_text()
    # The four devices' reports make one progress line.
    assert log.count("bucket 1/1 (capacity 16) done: 12/12 scenes") == 1, log[-3000:]
    assert sharded.num_devices == 4 and "4 × cpu" in sharded.device
    np.testing.assert_array_equal(sharded.num_points, padded.num_points)
    _assert_same_metrics(sharded, padded, exact=True)
    assert "refused: 'refine' refines points (refine=True)" in log and "4 devices" in log, log[
        -3000:
    ]


def test_refinement_sweeps_on_one_device(rig):
    """``refine=True`` (a least-squares solve per group) runs in the sweep and agrees with
    per-scene calls."""
    grid = dataclasses.replace(GRID, sigmas=(0.5,), counts=(7,))
    config = Config.paper(refine=True)
    result = sweep(rig, grid, methods={"refine": config}, buckets=(16,), timing=False)
    sub, keys = rig.select(GRID.views), grid.keys()
    for i in range(grid.num_scenes):
        scene = compact_scene(
            generate_scene(keys[i], sub, 7, 0.5, capacity=GRID.capacity), capacity=16
        )
        res = associate(sub, scene.xy, scene.mask, method=config, sigma=0.5)
        m = scene_metrics(sub, res, scene)
        assert result.metrics["refine"]["num_groups"][i] == int(res.num_groups)
        np.testing.assert_array_equal(result.metrics["refine"]["pg_f1"][i], np.asarray(m.pg_f1))
        np.testing.assert_allclose(
            result.metrics["refine"]["err3d"][i], np.asarray(m.err3d), rtol=1e-3, atol=1e-4
        )


def test_saved_results_load_back_identically(padded, tmp_path):
    save_results(padded, tmp_path)
    loaded = load_results(tmp_path)
    assert loaded == padded and loaded.grid == GRID and loaded.configs == ("paper", "loose")
    assert loaded != dataclasses.replace(loaded, wall_s=loaded.wall_s + 1)
    with open(tmp_path / "results.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 2 * GRID.num_scenes
    row = rows[GRID.num_scenes + 5]  # "loose", scene 5
    assert row["config"] == "loose" and float(row["sigma"]) == padded.sigma[5]
    assert float(row["pg_f1"]) == padded.metrics["loose"]["pg_f1"][5]
    assert float(row["time_s"]) == padded.time_s["loose"][5]
    meta = json.loads((tmp_path / "results.json").read_text())
    assert meta["versions"]["jax"] == jax.__version__ and "Config(" in meta["config_repr"]["paper"]


def test_summary_table(padded):
    table = summary_table(padded, sigmas=(0.5, 3.0, 9.0))
    lines = table.splitlines()
    assert lines[0].startswith("| σ (px) | method | G-F1 | mP-F1 | PG-P | PG-R | PG-F1 | 3DErr |")
    assert len(lines) == 2 + 2 * 2  # header, rule, 2 σ × 2 configs (σ = 9 is not in the grid)
    assert lines[2].startswith("| 0.5 | paper |")
