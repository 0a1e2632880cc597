"""Conventions every public name keeps (PIX's api_test): a docstring, options keyword-only,
and shapes stated in the docstring of every function that takes or returns arrays."""

import inspect
import re

import pytest

import cdog_jax
import cdog_jax.benchmark
import cdog_jax.calibration
import cdog_jax.geometry
import cdog_jax.graph
import cdog_jax.io
import cdog_jax.metrics
import cdog_jax.refine
import cdog_jax.synthetic
import cdog_jax.viz

MODULES = [
    cdog_jax,
    cdog_jax.geometry,
    cdog_jax.graph,
    cdog_jax.io,
    cdog_jax.refine,
    cdog_jax.synthetic,
    cdog_jax.metrics,
    cdog_jax.calibration,
    cdog_jax.viz,
    cdog_jax.benchmark,
]
PUBLIC = sorted(
    {
        (mod.__name__, name): obj
        for mod in MODULES
        for name in dir(mod)  # dir, not vars: it also lists the names a module loads on first use
        if not name.startswith("_")
        and (inspect.isfunction(obj := getattr(mod, name)) or inspect.isclass(obj))
    }.items()
)
FUNCTIONS = [(key, obj) for key, obj in PUBLIC if inspect.isfunction(obj)]
SHAPE = re.compile(r"\((\*|[A-Z]\b|[A-Z],|\d|\))")


@pytest.mark.parametrize("key, obj", PUBLIC, ids=[f"{m}.{n}" for (m, n), _ in PUBLIC])
def test_has_docstring(key, obj):
    assert inspect.getdoc(obj), f"{key} has no docstring"


@pytest.mark.parametrize("key, fn", FUNCTIONS, ids=[f"{m}.{n}" for (m, n), _ in FUNCTIONS])
def test_options_are_keyword_only(key, fn):
    for p in inspect.signature(fn).parameters.values():
        if p.default is not inspect.Parameter.empty:
            assert p.kind == inspect.Parameter.KEYWORD_ONLY, (
                f"{key}: option {p.name!r} must be keyword-only"
            )


@pytest.mark.parametrize("key, fn", FUNCTIONS, ids=[f"{m}.{n}" for (m, n), _ in FUNCTIONS])
def test_docstring_states_shapes(key, fn):
    sig = inspect.signature(fn)
    annotations = " ".join(str(p.annotation) for p in sig.parameters.values()) + str(
        sig.return_annotation
    )
    if "Array" in annotations or "Rig" in annotations:
        assert SHAPE.search(inspect.getdoc(fn)), f"{key}: docstring states no shape"


@pytest.mark.parametrize("module", MODULES + [cdog_jax.baselines], ids=lambda m: m.__name__)
def test_no_subpackage_is_a_name_of_all(module):
    # Subpackages stay reachable as attributes (cdog_jax.io, cdog_jax.geometry, ...); a star
    # import gives functions, classes and constants only.
    names = getattr(module, "__all__", [])
    assert not [name for name in names if inspect.ismodule(getattr(module, name))], names


def test_the_public_surface_stays_small():
    # Every public function, class and constant of the public modules, each counted once
    # where a module re-exports another's (cdog_jax.Rig is cdog_jax.geometry.Rig).
    surface = {
        (name, id(obj))
        for module in MODULES + [cdog_jax.baselines]
        for name in dir(module)
        if not name.startswith("_") and not inspect.ismodule(obj := getattr(module, name))
    }
    assert len(surface) <= 150, sorted(name for name, _ in surface)
