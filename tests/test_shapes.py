"""Padded shapes: ``associate`` / ``associate_batch`` run at a capacity from a fine ladder
and pad the batch, and return bitwise what the unpadded program returns."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import random_scene, ring_rig, run_with_xla_defaults

from cdog_jax import Config, associate, associate_batch
from cdog_jax._associate import (
    _associate_extras_jit,
    _associate_jit,
    _check_extras,
    _prepare,
    associate_batch_at,
)
from cdog_jax._runtime.shapes import chunk_size, ladder_rung, scene_capacity, slot_capacity

RIG = ring_rig(5)
P = 13  # on no ladder: associate runs at 32, associate_batch at 16


def _unpadded(xy, mask, config, sigma=1.0, dist=None, weights=None, min_views=2):
    """The jitted pipeline at the caller's own shapes (what associate ran before padding)."""
    static, thresholds = _prepare(config, sigma, None, np.float32)
    extras = _check_extras(dist, weights, min_views, mask.shape, np.float32)
    if extras is None:
        return _associate_jit(RIG, xy, mask, thresholds, method=static)
    return _associate_extras_jit(RIG, xy, mask, thresholds, *extras, method=static)


DISCRETE = ("labels", "groups", "valid", "n_views", "num_groups", "status")
FLOATS = ("points3d", "bpe", "err_px", "sigma_px", "tau_px")


def _assert_same(got, want, float_rtol=0.0):
    """Bitwise equal, except floats within ``float_rtol`` where given."""
    for name in DISCRETE + FLOATS:
        a, b = np.asarray(getattr(got, name)), np.asarray(getattr(want, name))
        assert a.shape == b.shape, name
        if name in FLOATS and float_rtol:
            np.testing.assert_allclose(a, b, rtol=float_rtol, atol=0.0, err_msg=name)
        else:
            np.testing.assert_array_equal(a, b, err_msg=name)


def test_ladders():
    assert [slot_capacity(p) for p in (1, 5, 7, 32, 33, 64, 65, 118, 129, 130, 257, 600)] == [
        4,
        6,
        8,
        32,
        48,
        64,
        80,
        128,
        136,
        136,
        272,
        608,
    ]
    # One scene alone: 32, 64 or 128 up to 128 slots (few programs for a notebook's loop),
    # the fine rungs above.
    assert [scene_capacity(p) for p in (1, 5, 32, 33, 64, 65, 128, 129, 130, 600)] == [
        32,
        32,
        32,
        64,
        64,
        128,
        128,
        136,
        136,
        608,
    ]
    assert len({scene_capacity(n) for n in range(1, 129)}) == 3
    capacities = [slot_capacity(n) for n in range(65, 4097)]
    assert all(n <= c < 1.25 * n for n, c in enumerate(capacities, start=65))
    # Above 128 slots less than a sixteenth of padding: the pairwise work within 1.13×.
    assert all(c < n * 17 / 16 for n, c in enumerate(capacities, start=65) if n > 128)
    assert all(slot_capacity(c) == c for c in capacities)  # a rung pads to itself
    # Four programs per doubling up to 128 (80, 96, 112, 128), sixteen above (136, 144, …).
    assert len(set(capacities)) == 4 + 16 * 5
    assert [chunk_size(b, 16) for b in (1, 2, 3, 5, 16, 17, 100)] == [1, 2, 3, 6, 16, 16, 16]
    assert chunk_size(9, 10) == 10
    rungs = [ladder_rung(n) for n in range(1, 4097)]
    assert all(
        n <= r <= max(1.5 * n, 2) for n, r in enumerate(rungs, start=1)
    )  # less than half padding
    assert all(ladder_rung(r) == r for r in rungs)  # a rung pads to itself
    assert len(set(rungs)) == 24  # two programs per doubling: 1, 2, 3, 4, 6, …, 3072, 4096


def _scene(seed, clutter=0):
    xy, mask, _, _ = random_scene(RIG, 9, P, sigma=1.0, seed=seed, clutter=clutter)
    return np.asarray(xy, np.float32), mask


# extended() with a given σ: test_padded_batch_is_bitwise_one_scene_at_a_time; paper()'s
# stages are a subset of these two presets'.
@pytest.mark.parametrize(
    "config, sigma, seed",
    [(Config.extended(), "auto", 1), (Config.reference(), 1.0, 2)],
    ids=["extended-auto", "reference"],
)
def test_padded_capacity_is_bitwise_unpadded(config, sigma, seed):
    xy, mask = _scene(seed, clutter=1)
    # σ's estimate sums over all (padded) samples: its float sums may group terms differently.
    rtol = 1e-6 if sigma == "auto" else 0.0
    _assert_same(
        associate(RIG, xy, mask, method=config, sigma=sigma),
        _unpadded(xy, mask, config, sigma),
        rtol,
    )


def test_padded_capacity_with_dist_weights_min_views():
    xy, mask = _scene(4)
    dist = np.tile(np.array([[1e-3, 0.0, 0.0, 0.0, 0.0]], np.float32), (RIG.num_views, 1))
    weights = np.random.default_rng(0).uniform(0.5, 1.0, mask.shape).astype(np.float32)
    kwargs = dict(dist=dist, weights=weights, min_views=3)
    _assert_same(
        associate(RIG, xy, mask, method=Config.extended(), **kwargs),
        _unpadded(xy, mask, Config.extended(), **kwargs),
    )


def padded_batch_is_bitwise_one_scene_at_a_time():
    scenes = [
        _scene(seed) for seed in range(5)
    ]  # 5 scenes, batch_size 2: chunks of 2, one padded scene
    xy, mask = np.stack([s[0] for s in scenes]), np.stack([s[1] for s in scenes])
    sigma = jnp.asarray([1.0, 0.8, 1.2, 1.0, 0.9], jnp.float32)
    batch = associate_batch(RIG, xy, mask, method=Config.extended(), sigma=sigma, batch_size=2)
    assert batch.labels.shape == (5, RIG.num_views, P)
    for b in range(5):
        one = _unpadded(xy[b], mask[b], Config.extended(), float(sigma[b]))
        _assert_same(jax.tree.map(lambda a: a[b], batch), one)


def test_a_batch_read_on_the_host_is_the_batch():
    """``on_host`` (a caller that reads the results there) skips the transfer back, nothing
    else: the same values, as NumPy arrays."""
    xy, mask = _scene(5)
    xy, mask = np.stack([xy, xy[:, ::-1]]), np.stack([mask, mask[:, ::-1]])
    device = associate_batch_at(RIG, xy, mask, method=Config.extended(), sigma=1.0)
    host = associate_batch_at(RIG, xy, mask, method=Config.extended(), sigma=1.0, on_host=True)
    for d, h in zip(jax.tree.leaves(device), jax.tree.leaves(host)):
        assert isinstance(d, jax.Array) and type(h) is np.ndarray
        np.testing.assert_array_equal(np.asarray(d), h)


def test_padded_batch_is_bitwise_one_scene_at_a_time():
    """In a child process with XLA's defaults, the code users run: there, where XLA fuses a
    multiply and an add into one rounding depends on how the program is fused, and the
    vmapped program is fused differently from the single-scene one (with the suite's
    switches, tests/conftest.py, no multiply-add is fused at all)."""
    run_with_xla_defaults(__file__, "padded_batch_is_bitwise_one_scene_at_a_time")


def test_one_scene_batch_runs_the_single_scene_program():
    """A one-scene batch runs associate's program itself (same capacity): associate on the
    scene afterwards compiles nothing."""
    xy, mask = _scene(5)
    batch = associate_batch(RIG, xy[None], mask[None], method=Config.extended(), sigma=1.0)
    compiles = []
    listener = lambda name, secs, **kw: (  # noqa: E731
        compiles.append(name) if name == "/jax/core/compile/backend_compile_duration" else None
    )
    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        one = associate(RIG, xy, mask, method=Config.extended(), sigma=1.0)
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
    assert compiles == []
    _assert_same(jax.tree.map(lambda a: a[0], batch), one)
    assert batch.labels.shape == (1, RIG.num_views, P) and isinstance(batch.labels, jax.Array)


def test_capacity_falls_back_to_the_unpadded_shape_only_where_the_budget_needs_it():
    from cdog_jax._associate import _capacity
    from cdog_jax._runtime.memory import estimate_peak_bytes

    config = Config.extended()
    at_33, at_48 = (estimate_peak_bytes(10, p, config) for p in (33, 48))
    between = (at_33 + at_48) / 2 / 1e9
    assert _capacity("associate", 10, 33, config, np.float32, 1, 2 * at_48 / 1e9, None) == 48
    assert _capacity("associate", 10, 33, config, np.float32, 1, between, None) == 33
    with pytest.raises(MemoryError, match="10 views × 33 slots"):
        _capacity("associate", 10, 33, config, np.float32, 1, at_33 / 2 / 1e9, None)


def test_frames_within_one_rung_compile_one_program():
    compiles = []
    listener = lambda name, secs, **kw: (
        compiles.append(name) if name == "/jax/core/compile/backend_compile_duration" else None
    )  # noqa: E731
    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        xy, mask = _scene(6)
        for count in (
            9,
            10,
            11,
            12,
        ):  # shapes no other test uses: any per-shape program would compile here
            associate(RIG, xy[:, :count], mask[:, :count], method=Config.paper(), sigma=1.0)
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
    assert len(compiles) <= 1, compiles  # the 32-slot program (none if already compiled)


def test_trailing_empty_slots_are_left_out(monkeypatch):
    """Slots that no view fills at the end of ``P`` are not sent to the program: 13 slots in
    use of 40 run at 32 slots (not 64), alone and one at a time in a batch, and the result
    is bitwise that of the program at 40 slots (labels of the empty slots -1, the extra
    group rows empty)."""
    import cdog_jax._associate as associate_module

    scenes = [_scene(seed, clutter=1) for seed in (6, 7)]
    wide = [
        (np.pad(xy, ((0, 0), (0, 27), (0, 0))), np.pad(mask, ((0, 0), (0, 27))))
        for xy, mask in scenes
    ]
    shapes = []
    program = associate_module._single_scene
    monkeypatch.setattr(
        associate_module,
        "_single_scene",
        lambda rig, xy, *rest: shapes.append(np.shape(xy)) or program(rig, xy, *rest),
    )
    config = Config.paper()
    got = associate(RIG, *wide[0], method=config)
    assert shapes == [(RIG.num_views, 32, 2)]
    _assert_same(got, _unpadded(*wide[0], config))
    batch = associate_batch(
        RIG,
        np.stack([w[0] for w in wide]),
        np.stack([w[1] for w in wide]),
        method=config,
        batch_size=1,
    )
    for b, (xy, mask) in enumerate(wide):
        _assert_same(jax.tree.map(lambda a: a[b], batch), _unpadded(xy, mask, config))
    assert shapes[1:] == [(RIG.num_views, 32, 2)] * 2  # one at a time: associate's rung
