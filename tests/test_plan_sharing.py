"""A plan that runs a stage more than once before its last fit compiles that stage once (a
loop over the steps that switches on the step), with the results of running the stages one
after another, bit for bit."""

import jax
import numpy as np
from helpers import random_scene, ring_rig

from cdog_jax import Config, associate_traced
from cdog_jax.cdog import _pipeline as _cdog
from cdog_jax.cdog._pipeline import STAGES, make_config
from cdog_jax.cdog._stage import Stage, always

RIG = ring_rig(5)
P = 12


def _equations(jaxpr):
    """Every equation of ``jaxpr`` and of the jaxprs nested in it."""
    for eqn in jaxpr.eqns:
        yield eqn
        for value in eqn.params.values():
            for sub in value if isinstance(value, (tuple, list)) else (value,):
                inner = getattr(sub, "jaxpr", None)
                if inner is not None:
                    yield from _equations(getattr(inner, "jaxpr", inner))


def _trace(config, xy, mask, sigma=1.0):
    return jax.make_jaxpr(lambda x, m, t: associate_traced(RIG, x, m, t, config))(
        xy, mask, config.thresholds(sigma)
    )


def test_a_stage_listed_twice_is_traced_once():
    calls = []

    def counting(scene, state, options):
        calls.append(1)
        return state

    count = Stage("count", counting, None, always)
    by_name = {stage.name: stage for stage in STAGES}
    stages = (
        by_name["graph"],
        count,
        by_name["fit"],
        count._replace(name="count_again"),
        by_name["fit"]._replace(name="refit"),
        by_name["validity_gate"],
    )
    Counted = make_config(stages, name="Counted", base=Config)
    xy, mask, _, _ = random_scene(RIG, 6, P, sigma=1.0, seed=1)
    _trace(Counted(), xy, mask)
    assert len(calls) == 1


def test_regrouping_reuses_the_graph_stage_and_the_switch_stays_one_under_vmap():
    xy, mask, _, _ = random_scene(RIG, 6, P, sigma=1.0, seed=1)
    config = Config.extended()
    graphs = [
        e
        for e in _equations(_trace(config, xy, mask).jaxpr)
        if e.params.get("name") == "graph_groups"
    ]
    assert len(graphs) == 1  # the first pass and regrouping's
    head, tail = _cdog._split_at_last_fit(_cdog.plan(config))
    assert [stage.name for stage, _ in tail] == ["refit", "validity_gate"]  # inlined
    steps = _cdog._flat_steps(head)
    distinct = len(set(steps))
    assert distinct < len(steps)
    batched = jax.make_jaxpr(
        jax.vmap(lambda x, m, t: associate_traced(RIG, x, m, t, config), in_axes=(0, 0, None))
    )(np.stack([xy, xy]), np.stack([mask, mask]), config.thresholds(1.0))
    switches = [
        e
        for e in _equations(batched.jaxpr)
        if e.primitive.name == "cond" and len(e.params["branches"]) == distinct
    ]
    assert len(switches) == 1  # not turned into a select of every branch


def test_shared_plan_equals_the_stages_inlined(monkeypatch):
    config = Config.paper(regroup=True, recover=True)
    scenes = [
        random_scene(RIG, n, P, sigma=s, seed=20 + n, clutter=2) for n, s in [(9, 2.0), (10, 3.0)]
    ]
    run = jax.jit(associate_traced, static_argnums=4)
    shared = [
        run(RIG, xy, mask, config.thresholds(s), config)
        for (xy, mask, _, _), s in zip(scenes, (2.0, 3.0))
    ]
    monkeypatch.setattr(_cdog, "_has_repeats", lambda steps: False)
    jax.clear_caches()
    inline = [
        run(RIG, xy, mask, config.thresholds(s), config)
        for (xy, mask, _, _), s in zip(scenes, (2.0, 3.0))
    ]
    assert any(int(r.num_groups) > 0 for r in shared)
    for a, b in zip(shared, inline):
        for fa, fb in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
            assert np.array_equal(np.asarray(fa), np.asarray(fb), equal_nan=True)
