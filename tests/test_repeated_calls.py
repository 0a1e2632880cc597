"""A frame loop in one process: after the first call nothing is traced or compiled again
and the process's memory mappings stay flat (every compiled program maps its code; a
program compiled on every call used to exhaust the kernel's 65,530 mappings after a few
hundred frames)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import memory_mappings

import cdog_jax
from cdog_jax import associate_classes
from cdog_jax.synthetic import DEFAULT_BOX, default_rig

M, C, K = 3, 4, 2  # views, classes, people
LOWERING = (
    "/jax/core/compile/jaxpr_to_mlir_module_duration"  # every new program, cached on disk or not
)


@pytest.fixture(scope="module")
def frame():
    """One frame of ``K`` people with ``C`` joints each, slots shuffled per view; the per-view
    instance of every detection is its person."""
    rig = default_rig(num_views=M)
    rng = np.random.default_rng(3)
    lo, hi = (np.asarray(b) for b in DEFAULT_BOX)
    X = rng.uniform(lo, hi, (C * K, 3))
    xy, _ = cdog_jax.project(rig, jnp.asarray(X, jnp.float32))
    xy = np.asarray(xy) + rng.normal(0.0, 0.5, (M, C * K, 2))
    truth = np.broadcast_to(np.arange(C * K), (M, C * K)).copy()  # c · K + k
    for m in range(M):
        order = rng.permutation(C * K)
        xy[m], truth[m] = xy[m, order], truth[m, order]
    mask = np.ones((1, M, C * K), bool)
    return rig, xy[None].astype(np.float32), mask, truth[None] // K, truth[None] % K


def _loop(call, count):
    """``call()`` once to warm up, then ``count`` times: ``(programs lowered, mappings
    before, mappings after)`` of the repeated calls."""
    call()
    lowered = []
    listener = lambda name, secs, **kw: lowered.append(name) if name == LOWERING else None  # noqa: E731
    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        before = memory_mappings()
        for _ in range(count):
            call()
        after = memory_mappings()
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
    return len(lowered), before, after


def test_default_arguments_compile_once_and_keep_memory_flat(frame):
    """``associate_classes`` with its defaults (σ estimated per frame) for 200 frames."""
    rig, xy, mask, classes, _ = frame
    lowered, before, after = _loop(lambda: associate_classes(rig, xy, mask, classes), 200)
    assert lowered == 0
    if before is not None:
        assert after - before < 50, (before, after)  # about 100 more per call when it leaked


@pytest.mark.parametrize("estimator", ["auto", "robust"])
def test_person_vote_and_lens_compile_once(frame, estimator):
    """With instances (the person vote), a lens and either σ estimator, nothing is compiled
    after the first frame."""
    rig, xy, mask, classes, person = frame
    dist = np.zeros((M, 5), np.float32)
    dist[:, 0] = 1e-3
    method = cdog_jax.Config.paper().replace(sigma_mode=estimator)
    call = lambda: associate_classes(
        rig, xy, mask, classes, instances=person, dist=dist, method=method
    )  # noqa: E731
    lowered, before, after = _loop(call, 20)
    assert lowered == 0
    if before is not None:
        assert after - before < 20, (before, after)
