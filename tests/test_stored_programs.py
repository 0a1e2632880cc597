"""Programs stored with ``jax.export`` (``cdog_jax/_runtime/stored_programs.py``): a later process
loads the lowered program instead of tracing, with bitwise the same results; stale,
corrupt or foreign entries are never used."""

import dataclasses
import os
import subprocess
import sys
from unittest import mock

import numpy as np
import pytest
from helpers import random_scene, ring_rig

import cdog_jax
from cdog_jax import Config
from cdog_jax._associate import _associate_jit, _prepare
from cdog_jax._runtime import stored_programs as stored

RIG = ring_rig(4)
P = 20  # padded to 32 slots


@pytest.fixture
def fresh_store(tmp_path, monkeypatch):
    """Stored programs in an empty folder, none loaded in this process yet."""
    monkeypatch.setenv("CDOG_JAX_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(stored, "_loaded", {})
    monkeypatch.setattr(stored, "_keys", {})
    folder = stored.stored_programs_dir()
    assert folder is not None and folder.is_relative_to(tmp_path)
    return folder


def _fields(result):
    return {f.name: np.asarray(getattr(result, f.name)) for f in dataclasses.fields(result)}


def _assert_bitwise(a, b):
    fa, fb = _fields(a), _fields(b)
    for name in fa:
        assert fa[name].dtype == fb[name].dtype and np.array_equal(fa[name], fb[name]), name


def _direct(xy, mask, sigma, method):
    static, thresholds = _prepare(method, sigma, None, np.float32)
    padded_xy = np.pad(xy, ((0, 0), (0, 32 - P), (0, 0)))
    padded_mask = np.pad(mask, ((0, 0), (0, 32 - P)))
    return cdog_jax._runtime.shapes.trim(
        _associate_jit(RIG, padded_xy, padded_mask, thresholds, method=static), P
    )


def test_stored_program_is_written_then_loaded_without_tracing(fresh_store):
    xy, mask, _, _ = random_scene(RIG, 12, P, sigma=1.0, seed=3)
    method = Config.paper()
    first = cdog_jax.associate(RIG, xy, mask, sigma=1.0, method=method)
    files = list(fresh_store.glob("*.jaxexport"))
    assert len(files) == 1 and stored.loaded_programs() == 1
    _assert_bitwise(first, _direct(xy, mask, 1.0, method))

    # As a new process would: nothing loaded yet; the method is never traced again.
    stored._loaded.clear()
    with mock.patch.object(Config, "associate_scene", side_effect=AssertionError("traced again")):
        again = cdog_jax.associate(RIG, xy, mask, sigma=1.0, method=method)
    _assert_bitwise(first, again)
    assert list(fresh_store.glob("*.jaxexport")) == files


def test_a_corrupt_entry_is_exported_again(fresh_store):
    xy, mask, _, _ = random_scene(RIG, 12, P, sigma=1.0, seed=4)
    method = Config.paper()
    first = cdog_jax.associate(RIG, xy, mask, sigma=1.0, method=method)
    (path,) = fresh_store.glob("*.jaxexport")
    path.write_bytes(path.read_bytes()[:1000])  # an interrupted writer from elsewhere
    stored._loaded.clear()
    again = cdog_jax.associate(RIG, xy, mask, sigma=1.0, method=method)
    _assert_bitwise(first, again)
    assert path.stat().st_size > 1000


def test_every_input_that_changes_the_program_changes_the_key(fresh_store):
    xy, mask, _, _ = random_scene(RIG, 12, P, sigma=1.0, seed=5)
    cdog_jax.associate(RIG, xy, mask, sigma=1.0, method=Config.paper())
    cdog_jax.associate(
        RIG, xy, mask, sigma=2.0, method=Config.paper(delta=0.7)
    )  # numbers only: same program
    assert len(list(fresh_store.glob("*.jaxexport"))) == 1
    cdog_jax.associate(
        RIG, xy, mask, sigma="auto", method=Config.paper()
    )  # σ estimated: another structure
    xy40, mask40, _, _ = random_scene(RIG, 12, 40, sigma=1.0, seed=5)
    cdog_jax.associate(RIG, xy40, mask40, sigma=1.0, method=Config.paper())  # 64 slots
    cdog_jax.associate(
        RIG, xy, mask, sigma=1.0, method=Config.paper(), min_views=3
    )  # the finishing program
    assert len(list(fresh_store.glob("*.jaxexport"))) == 4
    stored._keys.clear()  # as a new process with edited source would start
    with mock.patch.object(stored, "_package_source_hash", return_value="edited source"):
        cdog_jax.associate(RIG, xy, mask, sigma=1.0, method=Config.paper())
    assert len(list(fresh_store.glob("*.jaxexport"))) == 5


def test_nothing_is_stored_when_the_cache_is_off_or_the_method_is_foreign(fresh_store, monkeypatch):
    # Imported by the name tests/methods/test_new_method.py uses: one module, one registration.
    sys.path.insert(0, os.path.join(os.path.dirname(__file__), "methods"))
    from mutual_nn_method import MutualNearest

    xy, mask, _, _ = random_scene(RIG, 12, P, sigma=1.0, seed=6)
    cdog_jax.associate(RIG, xy, mask, sigma=1.0, method=MutualNearest())  # code outside the package
    assert not fresh_store.exists() or not list(fresh_store.glob("*.jaxexport"))
    monkeypatch.setenv("CDOG_JAX_CACHE", "0")
    assert stored.stored_programs_dir() is None
    cdog_jax.associate(RIG, xy, mask, sigma=1.0, method=Config.paper())
    assert not fresh_store.exists() or not list(fresh_store.glob("*.jaxexport"))


def test_a_second_process_loads_the_program_and_agrees(fresh_store, tmp_path):

    script = (
        "import sys, numpy as np, cdog_jax\n"
        "cdog_jax.enable_compilation_cache()\n"  # as a script does: importing the package does not
        "sys.path.insert(0, sys.argv[2])\n"
        "from helpers import random_scene, ring_rig\n"
        "xy, mask, _, _ = random_scene(ring_rig(4), 12, 20, sigma=1.0, seed=7)\n"
        "r = cdog_jax.associate(ring_rig(4), xy, mask, sigma=1.0, method=cdog_jax.Config.paper())\n"
        "np.savez(sys.argv[1], labels=np.asarray(r.labels), points3d=np.asarray(r.points3d))\n"
    )
    tests = os.path.dirname(__file__)
    outputs, written = [], []
    for run in range(2):
        out = tmp_path / f"run{run}.npz"
        subprocess.run([sys.executable, "-c", script, str(out), tests], check=True)
        outputs.append(np.load(out))
        (path,) = fresh_store.glob("*.jaxexport")
        written.append(path.stat().st_mtime_ns)
    assert written[0] == written[1]  # the second process loaded it, wrote nothing
    for name in ("labels", "points3d"):
        assert np.array_equal(outputs[0][name], outputs[1][name])


def test_a_stored_batch_program_agrees_with_its_first_run(fresh_store):
    scenes = [random_scene(RIG, 12, P, sigma=1.0, seed=s) for s in range(3)]
    xy, mask = np.stack([s[0] for s in scenes]), np.stack([s[1] for s in scenes])
    first = cdog_jax.associate_batch(RIG, xy, mask, sigma=1.0, method=Config.paper(), batch_size=2)
    assert len(list(fresh_store.glob("*.jaxexport"))) == 1  # one program: chunks of 2 scenes
    stored._loaded.clear()
    with mock.patch.object(Config, "associate_scene", side_effect=AssertionError("traced again")):
        again = cdog_jax.associate_batch(
            RIG, xy, mask, sigma=1.0, method=Config.paper(), batch_size=2
        )
    _assert_bitwise(first, again)
    assert first.labels.shape == (3, RIG.num_views, P)


@pytest.mark.parametrize("sigma_mode", ["auto", "robust"])
def test_the_sigma_programs_are_stored_and_agree_bitwise(fresh_store, sigma_mode):
    # The class association's σ samples and fit (tuple outputs, no method) go through the
    # store too: a later process loads them instead of tracing the EM again.
    from cdog_jax.people import _classes

    rng = np.random.default_rng(8)
    F, M, Pv = 3, RIG.num_views, 12
    xy = rng.uniform(0, 640, (F, M, Pv, 2)).astype(np.float32)
    mask = rng.random((F, M, Pv)) < 0.8
    classes = rng.integers(0, 3, (F, M, Pv))

    def run():
        return cdog_jax.associate_classes(
            RIG, xy, mask, classes, method=Config.best(sigma_mode=sigma_mode)
        )

    first = run()
    assert len(list(fresh_store.glob("*.jaxexport"))) == 3  # samples, fit, association
    stored._loaded.clear()
    with (
        mock.patch.object(
            _classes, "sigma_from_samples", side_effect=AssertionError("traced again")
        ),
        mock.patch.object(
            _classes, "robust_sigma_from_samples", side_effect=AssertionError("traced again")
        ),
        mock.patch.object(_classes, "nearest_samples", side_effect=AssertionError("traced again")),
        mock.patch.object(
            _classes, "nearest_two_samples", side_effect=AssertionError("traced again")
        ),
    ):
        again = run()
    _assert_bitwise(first.association, again.association)
    stored._loaded.clear()
    with mock.patch.object(stored, "stored_programs_dir", return_value=None):  # plain jit
        direct = run()
    _assert_bitwise(first.association, direct.association)
