"""Every writer of the library replaces its file whole or not at all: a write that fails
mid-way (a full disk, simulated with a file-size limit, or a failing serialiser) leaves the
previous file intact and no temporary file behind."""

import json
import os
import resource
import signal
from types import SimpleNamespace

import numpy as np
import pytest

from cdog_jax.io import save_association_csv, save_association_json, save_association_npz, save_rig
from cdog_jax.io._atomic import atomic_write
from cdog_jax.synthetic import IMAGE_SIZE, default_rig

RIG = default_rig()
M, P, G = 10, 40, 30


def _assoc():
    """A one-scene result with ``G`` valid groups (fields of cdog_jax.Association)."""
    groups = np.tile(np.arange(G)[:, None], (1, M))
    return SimpleNamespace(
        labels=np.tile(np.where(np.arange(P) < G, np.arange(P), -1), (M, 1)),
        groups=groups,
        valid=np.ones(G, bool),
        points3d=np.random.default_rng(0).normal(size=(G, 3)),
        bpe=np.full(G, 0.25),
        err_px=np.full(G, 0.5),
        n_views=np.full(G, M),
        num_groups=np.int32(G),
        sigma_px=np.float32(1.0),
        tau_px=np.float32(2.0),
        status=np.int32(0),
    )


XY = np.random.default_rng(1).uniform(0, 600, (M, P, 2))
MASK = np.ones((M, P), bool)


def _figure(path):
    import jax.numpy as jnp

    from cdog_jax import Association
    from cdog_jax.viz import plot_association

    a = _assoc()
    G_full = M * P // 2  # the static group capacity of an Association
    pad = lambda v, fill: np.concatenate([v, np.full((G_full - G, *v.shape[1:]), fill, v.dtype)])  # noqa: E731
    result = Association(
        labels=jnp.asarray(a.labels, jnp.int32),
        groups=jnp.asarray(pad(a.groups, -1), jnp.int32),
        valid=jnp.asarray(pad(a.valid, False)),
        points3d=jnp.asarray(pad(a.points3d, 0.0), jnp.float32),
        bpe=jnp.asarray(pad(a.bpe, 0.0), jnp.float32),
        err_px=jnp.asarray(pad(a.err_px, 0.0), jnp.float32),
        n_views=jnp.asarray(pad(a.n_views, 0), jnp.int32),
        num_groups=jnp.int32(G),
        sigma_px=jnp.float32(1.0),
        tau_px=jnp.float32(2.0),
        status=jnp.int32(0),
    )
    plot_association(
        RIG,
        jnp.asarray(XY, jnp.float32),
        jnp.asarray(MASK),
        result,
        image_size=IMAGE_SIZE,
        path=path,
    )


WRITERS = {
    "association.json": lambda p: save_association_json(p, _assoc(), XY, MASK),
    "association.npz": lambda p: save_association_npz(p, _assoc(), xy=XY, mask=MASK),
    "association.csv": lambda p: save_association_csv(p, _assoc()),
    "rig.json": lambda p: save_rig(p, RIG, format="json", image_size=IMAGE_SIZE),
    "rig.npz": lambda p: save_rig(p, RIG, format="npz", image_size=IMAGE_SIZE),
    "calibration.toml": lambda p: save_rig(p, RIG, format="anipose", image_size=IMAGE_SIZE),
    "figure.png": _figure,
}
FOLDER_WRITERS = {
    "easyvis": (lambda p: save_rig(p, RIG, format="easyvis"), "K0.txt"),
    "colmap": (lambda p: save_rig(p, RIG, format="colmap", image_size=IMAGE_SIZE), "cameras.txt"),
    "easymocap": (lambda p: save_rig(p, RIG, format="easymocap"), "intri.yml"),
}


def _with_file_size_limit(limit, fn):
    """Run ``fn`` with files limited to ``limit`` bytes: writes beyond fail with EFBIG, as
    on a full disk."""
    old_limit = resource.getrlimit(resource.RLIMIT_FSIZE)
    old_handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, old_limit[1]))
    try:
        fn()
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, old_limit)
        signal.signal(signal.SIGXFSZ, old_handler)


@pytest.mark.parametrize("name", list(WRITERS))
def test_a_full_disk_keeps_the_previous_file(tmp_path, name):
    path = tmp_path / name
    WRITERS[name](path)
    size = os.path.getsize(path)
    assert size > 600
    old = b"the previous result"
    path.write_bytes(old)
    with pytest.raises(OSError):
        _with_file_size_limit(300, lambda: WRITERS[name](path))
    assert path.read_bytes() == old
    assert os.listdir(tmp_path) == [name]
    WRITERS[name](path)  # and a write that succeeds replaces it whole
    assert os.path.getsize(path) == size


@pytest.mark.parametrize("name", list(FOLDER_WRITERS))
def test_a_full_disk_keeps_the_previous_rig_folder_files(tmp_path, name):
    write, file = FOLDER_WRITERS[name]
    folder = tmp_path / name
    write(folder)
    old = (folder / file).read_bytes()
    listing = sorted(os.listdir(folder))
    with pytest.raises(OSError):
        _with_file_size_limit(100, lambda: write(folder))
    assert (folder / file).read_bytes() == old
    assert sorted(os.listdir(folder)) == listing


def test_a_failing_serialiser_keeps_the_previous_file(tmp_path, monkeypatch):
    path = tmp_path / "out.json"
    path.write_text("old")

    def dump(obj, f, **kwargs):
        f.write('{"groups": [')
        raise RuntimeError("interrupted")

    monkeypatch.setattr(json, "dump", dump)
    with pytest.raises(RuntimeError, match="interrupted"):
        save_association_json(path, _assoc(), XY, MASK)
    assert path.read_text() == "old"
    assert os.listdir(tmp_path) == ["out.json"]

    monkeypatch.setattr(np, "savez", lambda f, **arrays: (f.write(b"PK partial"), 1 / 0))
    npz = tmp_path / "out.npz"
    npz.write_bytes(b"old")
    with pytest.raises(ZeroDivisionError):
        save_association_npz(npz, _assoc())
    assert npz.read_bytes() == b"old"
    assert sorted(os.listdir(tmp_path)) == ["out.json", "out.npz"]


def test_atomic_write_keeps_the_mode_and_writes_through_links(tmp_path):
    path = tmp_path / "a.txt"
    path.write_text("old")
    os.chmod(path, 0o640)
    link = tmp_path / "link.txt"
    link.symlink_to(path)
    with atomic_write(link, "w") as f:
        f.write("new")
    assert path.read_text() == "new" and link.is_symlink()
    assert os.stat(path).st_mode & 0o777 == 0o640
    fresh = tmp_path / "fresh.txt"
    with atomic_write(fresh, "w") as f:
        f.write("x")
    umask = os.umask(0)
    os.umask(umask)
    assert os.stat(fresh).st_mode & 0o777 == 0o666 & ~umask
