"""The persistent compilation cache: where it lives, how it is turned off, and that a second
process loads what the first compiled instead of compiling again."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from cdog_jax._compile_cache import cache_dir_from_environment, default_cache_dir


def test_folder_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.delenv("CDOG_JAX_CACHE", raising=False)
    monkeypatch.setenv("CDOG_JAX_CACHE_DIR", str(tmp_path / "here"))
    folder = cache_dir_from_environment()
    assert folder.parent == tmp_path / "here" and folder.name.startswith("jax-")
    monkeypatch.delenv("CDOG_JAX_CACHE_DIR")
    assert cache_dir_from_environment().parent == default_cache_dir()


@pytest.mark.parametrize("off", ["0", "false", "off", "no"])
def test_turned_off(monkeypatch, off):
    monkeypatch.setenv("CDOG_JAX_CACHE", off)
    assert cache_dir_from_environment() is None


_CHILD = textwrap.dedent(
    """
    import jax, jax.numpy as jnp
    hits = []
    jax.monitoring.register_event_listener(lambda name, **kw: hits.append(name) if name.endswith("cache_hits") else None)
    import cdog_jax
    from cdog_jax.geometry import triangulate
    from cdog_jax.synthetic import default_rig
    rig = default_rig()
    X, ok = jax.jit(triangulate)(rig, jnp.zeros((10, 4, 2)), jnp.ones((10, 4), bool))
    print("dir", jax.config.jax_compilation_cache_dir)
    print("hits", len(hits))
    """
)


def _run_child(env) -> dict:
    out = subprocess.run([sys.executable, "-c", _CHILD], env=env, capture_output=True, text=True, timeout=300, check=True)
    return dict(line.split(" ", 1) for line in out.stdout.splitlines())


def test_second_process_loads_the_compiled_program(tmp_path):
    env = dict(os.environ, CDOG_JAX_CACHE_DIR=str(tmp_path), CDOG_JAX_CACHE="1", JAX_PLATFORMS="cpu")
    first = _run_child(env)
    assert Path(first["dir"]).parent == tmp_path
    assert any(Path(first["dir"]).iterdir()), "the first process stored nothing"
    second = _run_child(env)
    assert int(second["hits"]) > int(first["hits"])
    off = _run_child(dict(env, CDOG_JAX_CACHE="0"))
    assert off["dir"] == "None" and int(off["hits"]) == 0


def test_no_cache_flag_turns_it_off(tmp_path):
    import jax

    from cdog_jax.cli import main
    from cdog_jax.io import save_rig_json
    from cdog_jax.synthetic import default_rig

    save_rig_json(tmp_path / "rig.json", default_rig())
    before = jax.config.jax_compilation_cache_dir
    try:
        assert main(["--no-cache", "rig", str(tmp_path / "rig.json")]) == 0
        assert jax.config.jax_compilation_cache_dir is None
    finally:
        jax.config.update("jax_compilation_cache_dir", before)
