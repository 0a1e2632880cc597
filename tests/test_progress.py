"""Progress of the long jobs: tqdm bars and a 'compiling' line on stderr in a terminal,
nothing otherwise; the many-frame associate gives the same result in chunks."""

import jax.numpy as jnp
import numpy as np
import pytest

from cdog_jax._runtime import progress as _progress
from cdog_jax.benchmark import SweepProgress
from cdog_jax.cli._associate_command import _associate_frames


@pytest.mark.parametrize("forced,expected", [("1", True), ("0", False)])
def test_interactive_follows_the_environment(monkeypatch, forced, expected):
    monkeypatch.setenv("CDOG_JAX_PROGRESS", forced)
    assert _progress.interactive() is expected


def test_not_a_terminal_is_quiet(monkeypatch, capsys):
    monkeypatch.delenv("CDOG_JAX_PROGRESS", raising=False)
    assert not _progress.interactive()  # pytest captures stderr: not a terminal
    with _progress.compiling("a program"):
        pass
    b = _progress.bar(3, "job")
    b.update(3)
    b.close()
    assert capsys.readouterr().err == ""


def test_terminal_shows_compiling_and_bars(monkeypatch, capsys):
    monkeypatch.setenv("CDOG_JAX_PROGRESS", "1")
    with _progress.compiling("a program"):
        pass
    callback, close = _progress.sweep_bar(10)
    callback(
        SweepProgress(
            bucket=0, num_buckets=2, capacity=20, scenes_done=4, num_scenes=10, elapsed_s=1.0
        )
    )
    callback(
        SweepProgress(
            bucket=1, num_buckets=2, capacity=50, scenes_done=10, num_scenes=10, elapsed_s=2.0
        )
    )
    close()
    err = capsys.readouterr().err
    assert "compiling a program" in err and "compiled a program in" in err
    assert "bucket 2/2 (capacity 50) done" in err and "10/10" in err


def test_many_frames_in_chunks_equal_one_call(monkeypatch, capsys):
    monkeypatch.setenv("CDOG_JAX_PROGRESS", "1")
    rng = np.random.default_rng(0)
    F = 45
    xy = jnp.asarray(rng.normal(size=(F, 3, 4, 2)))
    mask = jnp.asarray(rng.random((F, 3, 4)) < 0.5)
    weights = jnp.asarray(rng.random((F, 3, 4)))
    shapes = []

    def call(xy, mask, w):
        shapes.append(xy.shape[0])
        return {"s": jnp.sum(xy * w[..., None], axis=(1, 2, 3)), "n": jnp.sum(mask, axis=(1, 2))}

    whole = call(xy, mask, weights)
    shapes.clear()
    chunked = _associate_frames(call, xy, mask, weights, batch_size=1)
    assert len(shapes) > 1 and len(set(shapes)) == 1  # several calls, one shape (one compile)
    np.testing.assert_allclose(chunked["s"], whole["s"])
    np.testing.assert_array_equal(chunked["n"], whole["n"])
    assert "45/45" in capsys.readouterr().err
    shapes.clear()
    few = _associate_frames(call, xy[:3], mask[:3], weights[:3], batch_size=16)
    assert shapes == [3] and few["s"].shape == (3,)
