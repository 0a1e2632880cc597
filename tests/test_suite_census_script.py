"""Smoke test: experiments/suite_census.py, as a pytest plugin in a child pytest, counts
the tracing, lowering and compilation of a test and reports them per file."""

import os
import subprocess
import sys

HERE = os.path.dirname(__file__)
EXPERIMENTS = os.path.join(HERE, "..", "experiments")

_TINY_TEST = """
import jax
import jax.numpy as jnp

def test_one_program_and_one_operation():
    assert float(jax.jit(lambda x: jnp.sin(x).sum())(jnp.ones(5))) > 0
    assert float(jnp.cos(jnp.zeros(7))[0]) == 1.0

def test_a_stored_program():
    import numpy as np
    import cdog_jax
    from cdog_jax.synthetic import default_rig

    cdog_jax.enable_compilation_cache()
    rig = default_rig(num_views=3)
    xy = np.zeros((3, 2, 2), np.float32)
    cdog_jax.associate(rig, xy, np.ones((3, 2), bool), method="greedy")
"""


def test_census_counts_a_child_test(tmp_path, capsys):
    sys.path.insert(0, EXPERIMENTS)
    try:
        import suite_census
    finally:
        sys.path.remove(EXPERIMENTS)
    (tmp_path / "test_tiny.py").write_text(_TINY_TEST)
    out = tmp_path / "census"
    env = dict(
        os.environ,
        PYTHONPATH=os.path.abspath(EXPERIMENTS),
        SUITE_CENSUS_OUT=str(out),
        CDOG_JAX_CACHE_DIR=str(tmp_path / "cache"),
    )
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "-q",
            "-p",
            "suite_census",
            "-p",
            "no:cacheprovider",
            "test_tiny.py",
        ],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    totals, per_file = suite_census.summarise(out)
    assert list(per_file) == ["test_tiny.py"]
    assert totals["trace_n"] >= 1 and totals["lower_n"] >= 2  # the jitted function and cos
    assert totals["compile_small_n"] + totals["compile_program_n"] >= 2
    assert (
        0
        < totals["trace_s"]
        + totals["lower_s"]
        + totals["compile_small_s"]
        + totals["compile_program_s"]
        <= totals["wall_s"]
    )
    suite_census.main([str(out)])
    text = capsys.readouterr().out
    assert "| all tests |" in text and "| test_tiny.py |" in text
    assert suite_census.stored_program_files(out) == (1, 1)  # greedy's one-scene program
    assert "stored programs (function, method, shapes): 1 distinct, 1 of them" in text


def test_programs_are_summed_by_name_over_the_workers(tmp_path, capsys):
    sys.path.insert(0, EXPERIMENTS)
    try:
        import suite_census
    finally:
        sys.path.remove(EXPERIMENTS)
    (tmp_path / "gw0.json").write_text('{"tests/a.py::t": {"wall_s": 3.0}}')
    (tmp_path / "gw0.programs").write_text(
        '[["tests/a.py::t", "f", 1.0], ["tests/a.py::u", "g", 0.5], ["tests/a.py::t", "f", 2.0]]'
    )
    (tmp_path / "gw1.programs").write_text('[["tests/b.py::t", "f", 0.5]]')
    assert suite_census.programs_by_name(tmp_path) == [("f", 3, 3.5, 2), ("g", 1, 0.5, 1)]
    suite_census.main([str(tmp_path), "--programs", "1"])
    text = capsys.readouterr().out
    assert "| f | 3 | 4 | 2 |" in text and "| g |" not in text


def test_stored_programs_are_counted_by_the_files_that_meet_them(tmp_path):
    sys.path.insert(0, EXPERIMENTS)
    try:
        import suite_census
    finally:
        sys.path.remove(EXPERIMENTS)
    (tmp_path / "gw0.stored").write_text(
        '[["tests/a.py::t", "f best 4x3"], ["tests/a.py::u", "f best 4x8"], '
        '["tests/b.py::t", "f best 4x3"]]'
    )
    (tmp_path / "gw1.stored").write_text('[["tests/c.py::t", "g paper 2"]]')
    assert suite_census.stored_program_files(tmp_path) == (3, 2)
