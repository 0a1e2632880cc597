"""The persistent compilation cache: where it lives, how it is turned off, and that a second
process loads what the first compiled instead of compiling again."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from cdog_jax._runtime.compile_cache import (
    MIN_COMPILE_SECONDS,
    cache_dir_from_environment,
    default_cache_dir,
)


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
    from cdog_jax import Config, associate, enable_compilation_cache
    enable_compilation_cache()
    from cdog_jax.synthetic import default_rig, generate_scene
    rig = default_rig()
    scene = generate_scene(jax.random.PRNGKey(0), rig, 5, 1.0, capacity=8)
    associate(rig, scene.xy, scene.mask, method=Config.paper(), sigma=1.0)  # a program of seconds
    jnp.sin(jnp.arange(3.0)).block_until_ready()  # one operation outside jit: not stored
    folder = jax.config.jax_compilation_cache_dir
    print("dir", folder)
    print("hits", len(hits))
    print("min_s", jax.config.jax_persistent_cache_min_compile_time_secs)
    import os
    print("entries", " ".join(sorted(os.listdir(folder))) if folder else "")
    """
)


def _run_child(env) -> dict:
    out = subprocess.run(
        [sys.executable, "-c", _CHILD],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
    )
    return dict(line.split(" ", 1) for line in out.stdout.splitlines())


def test_second_process_loads_the_compiled_program(tmp_path):
    env = dict(
        os.environ, CDOG_JAX_CACHE_DIR=str(tmp_path), CDOG_JAX_CACHE="1", JAX_PLATFORMS="cpu"
    )
    first = _run_child(env)
    assert Path(first["dir"]).parent == tmp_path
    assert any(name.startswith("jit_call-") for name in first["entries"].split()), first["entries"]
    # Programs of one operation compile as fast as they load: not stored.
    assert float(first["min_s"]) == MIN_COMPILE_SECONDS > 0
    assert not any(name.startswith("jit_sin-") for name in first["entries"].split()), first[
        "entries"
    ]
    second = _run_child(env)
    assert int(second["hits"]) > int(first["hits"])
    off = _run_child(dict(env, CDOG_JAX_CACHE="0"))
    assert off["dir"] == "None" and int(off["hits"]) == 0


def test_no_cache_flag_turns_it_off(tmp_path):
    import jax

    from cdog_jax.cli import main
    from cdog_jax.io import save_rig
    from cdog_jax.synthetic import default_rig

    save_rig(tmp_path / "rig.json", default_rig(), format="json")
    before = jax.config.jax_compilation_cache_dir
    try:
        assert main(["--no-cache", "rig", str(tmp_path / "rig.json")]) == 0
        assert jax.config.jax_compilation_cache_dir is None
    finally:
        jax.config.update("jax_compilation_cache_dir", before)


def test_importing_the_package_changes_no_jax_setting():
    # The command line turns the cache on, a script calls enable_compilation_cache.
    code = (
        "import jax; before = {k: getattr(jax.config, k) for k in ('jax_compilation_cache_dir',"
        " 'jax_persistent_cache_min_compile_time_secs', 'jax_compilation_cache_max_size')}\n"
        "import cdog_jax\n"
        "after = {k: getattr(jax.config, k) for k in before}\n"
        "assert after == before, (before, after)\n"
        "assert cdog_jax.enable_compilation_cache() is not None and jax.config.jax_compilation_cache_dir\n"
    )
    env = dict(os.environ, CDOG_JAX_CACHE="1", JAX_PLATFORMS="cpu")
    subprocess.run(
        [sys.executable, "-c", code],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
