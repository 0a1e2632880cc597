"""``import cdog_jax`` loads what associating needs and nothing more: the figures, the file
formats, the benchmark, calibration (and optimistix), the command line and matplotlib load
on first use. The command line itself loads the file formats, not the sweep or the figures."""

import json
import subprocess
import sys

import pytest

_CHILD = """
import json, sys
import cdog_jax
before = sorted(sys.modules)
import cdog_jax.cli
cli = sorted(sys.modules)
figure = cdog_jax.plot_rig
import cdog_jax.benchmark
sweep = cdog_jax.benchmark.sweep
print(json.dumps({"before": before, "cli": cli, "after": sorted(sys.modules), "figure": f"{figure.__module__}.{figure.__name__}",
                  "listed": "plot_association" in dir(cdog_jax), "sweep": f"{sweep.__module__}.{sweep.__name__}",
                  "sweep_listed": "sweep" in dir(cdog_jax.benchmark) and "sweep" in cdog_jax.benchmark.__all__}))
"""
LATER = (
    "cdog_jax.io",
    "cdog_jax.viz",
    "cdog_jax.benchmark",
    "cdog_jax.calibration",
    "cdog_jax.cli",
    "cdog_jax.synthetic",
    "matplotlib",
    "optimistix",
)


@pytest.fixture(scope="module")
def loaded():
    """The modules a fresh process holds after each step of ``_CHILD``, and what it found."""
    done = subprocess.run(
        [sys.executable, "-c", _CHILD], capture_output=True, text=True, check=True
    )
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_import_leaves_figures_formats_and_tools_for_later(loaded):
    early = [
        m
        for m in loaded["before"]
        if m.split(".")[0] in ("matplotlib", "optimistix") or m.startswith(LATER)
    ]
    assert early == [], f"import cdog_jax loaded {early}"
    assert "cdog_jax._associate" in loaded["before"] and "cdog_jax.baselines" in loaded["before"]
    # The figures are still where users find them, and load when asked for.
    assert loaded["figure"] == "cdog_jax.viz._rig_plot.plot_rig" and loaded["listed"]
    assert "cdog_jax.viz" in loaded["after"]


def test_the_command_line_leaves_the_sweep_and_the_figures_for_later(loaded):
    early = [
        m
        for m in loaded["cli"]
        if m.split(".")[0] == "matplotlib"
        or m.startswith(
            (
                "cdog_jax.viz",
                "cdog_jax.benchmark._sweep",
                "cdog_jax.benchmark._grid",
                "cdog_jax.calibration",
            )
        )
    ]
    assert early == [], f"import cdog_jax.cli loaded {early}"
    assert (
        "cdog_jax.io._rig_files" in loaded["cli"] and "cdog_jax.benchmark._methods" in loaded["cli"]
    )
    assert loaded["sweep"] == "cdog_jax.benchmark._sweep.sweep" and loaded["sweep_listed"]


def test_an_unknown_name_is_an_attribute_error():
    import cdog_jax

    with pytest.raises(AttributeError, match="has no attribute 'plot_everything'"):
        cdog_jax.plot_everything  # noqa: B018


def test_a_star_import_still_brings_the_figures():
    names = {}
    exec("from cdog_jax import *", names)
    assert {"associate", "Config", "plot_rig", "plot_association"} <= set(names)
