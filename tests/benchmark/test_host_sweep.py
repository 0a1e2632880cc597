"""sweep_host: the compiled sweep's scenes and scores, one scene at a time (for host methods)."""

import numpy as np
import pytest

from cdog_jax.benchmark import Grid, sweep, sweep_host
from cdog_jax.benchmark._sweep import metric_fields
from cdog_jax.synthetic import default_rig

GRID = Grid(sigmas=(0.0, 2.0), counts=(3, 9), scenes=2, seed=4)


def test_host_sweep_equals_the_compiled_sweep_for_a_jittable_method():
    rig = default_rig(num_views=4)
    compiled = sweep(rig, GRID, methods=["greedy"], buckets=(6, 10), timing=False, progress=False)
    host = sweep_host(rig, GRID, ["greedy"], buckets=(6, 10))
    for name in ("sigma", "count", "scene", "num_points", "capacity"):
        np.testing.assert_array_equal(getattr(host, name), getattr(compiled, name), err_msg=name)
    assert host.configs == compiled.configs and host.buckets == compiled.buckets
    for field in metric_fields() + ("sigma_px_used", "tau_px_used", "num_groups"):
        a, b = host.metrics["greedy"][field], compiled.metrics["greedy"][field]
        assert a.dtype == b.dtype and a.shape == b.shape, field
        if field in ("err3d", "bpe_px"):  # float32 round-off of points (compiled apart)
            np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-4, err_msg=field)
        else:  # the same groups: the same scores
            np.testing.assert_allclose(a, b, rtol=1e-6, atol=0, err_msg=field)
    assert np.all(host.time_s["greedy"] > 0)


def test_host_sweep_runs_a_host_method_and_checks_its_scenes():
    rig = default_rig(num_views=3)
    result = sweep_host(
        rig, GRID.replace(sigmas=(1.0,), counts=(4,), scenes=1), ["exact"], buckets=(6,)
    )
    assert result.metrics["exact"]["pg_f1"].shape == (1,) and result.num_points[0] == 4
    assert np.isfinite(result.time_s["exact"]).all()
    with pytest.raises(ValueError, match="scene 0.*at most 15 points"):
        sweep_host(
            rig, GRID.replace(sigmas=(0.0,), counts=(20,), scenes=1), ["exact"], buckets=(20,)
        )
