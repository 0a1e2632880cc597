"""The method interface and the registry of named methods (docs/ARCHITECTURE.md).

A *method* turns one scene's detections into groups of detections of one 3D point. It is
an immutable, hashable description: its structure (which stages run, loop bounds, modes)
is a static argument of ``jax.jit``; its numbers (gates, fences, factors) become a
``NamedTuple`` of arrays, :meth:`Method.thresholds`, that the compiled program takes as a
traced input, so a sweep over them or over σ compiles once. Its one pure function,
:meth:`Method.associate_scene`, maps ``(rig, observations, thresholds)`` to an
:class:`~cdog_jax.Association`; :func:`cdog_jax.associate`, :func:`cdog_jax.associate_batch`,
:func:`cdog_jax.benchmark.sweep`, :func:`cdog_jax.calibration.calibrate` and the commands
check inputs, pad, batch and compile around it, whatever the method.

Every method's thresholds hold ``sigma_px`` (the noise σ, pixels; set per scene by the
callers), and ``min_parallax_deg`` and ``max_err_frac``, the numbers of the validity gate
that every group passes again after confidence weighting (ALGORITHM.md §12).

C-DOG's presets (:class:`cdog_jax.Config`) are methods; so is anything registered with
:func:`register_method`.
"""

from __future__ import annotations

import abc
import dataclasses
from collections.abc import Callable
from typing import ClassVar, NamedTuple

import jax
import numpy as np

from ._types import Array, Bool, Float


class Observations(NamedTuple):
    """One scene's detections, a pytree: ``xy (M, P, 2)`` pixels, ``mask (M, P)`` bool (the
    slot holds a detection; other slots may hold anything), and optional ``weights (M, P)``
    (non-negative confidences of the members' triangulation equations; ``None``: all 1)."""

    xy: Float[Array, "M P 2"]
    mask: Bool[Array, "M P"]
    weights: Float[Array, "M P"] | None = None


class Method(abc.ABC):
    """An association method. Subclasses are frozen dataclasses (hashable, compared by value).

    A subclass provides :meth:`structure`, :meth:`thresholds` and :meth:`associate_scene`;
    the defaults of the other hooks suit a method whose memory is dominated by a few
    ``(N, N)`` tables (``N = M·P``).
    """

    #: ``"given"``: σ comes from the caller (``thresholds.sigma_px``); ``"auto"``: the
    #: method estimates it from the scene. A dataclass field in subclasses.
    sigma_mode: str

    #: False for a method whose :meth:`associate_scene` runs NumPy on the host (e.g. an
    #: integer program): the entry points then call it eagerly, scene by scene, on host
    #: arrays (no ``jit``, no ``vmap``), and the compiled sweep refuses it
    #: (:func:`cdog_jax.benchmark.sweep_host` runs it).
    jittable: ClassVar[bool] = True

    @abc.abstractmethod
    def structure(self) -> "Method":
        """This method with its numbers reset to their defaults: the part a jit key needs."""

    @abc.abstractmethod
    def thresholds(self, sigma_px=0.0, *, dtype=None) -> tuple:
        """The numbers (and σ) as a ``NamedTuple`` of scalars of ``dtype`` (NumPy scalars,
        except that a JAX ``sigma_px`` stays a JAX array). Fields ``sigma_px``,
        ``min_parallax_deg`` and ``max_err_frac`` are required."""

    @abc.abstractmethod
    def associate_scene(self, rig, observations: Observations, thresholds: tuple):
        """The pure per-scene function: an :class:`~cdog_jax.Association` for one scene.
        Traced under ``jit``/``vmap``; no input checks; padded slots must change nothing."""

    def check_thresholds(self, thresholds: tuple) -> None:
        """Raise ``ValueError`` for a concrete threshold outside its range (callers pass
        user-given thresholds through here before any work). Default: finite numbers."""
        if not isinstance(thresholds, type(self.thresholds())):
            raise TypeError(f"thresholds must be a {type(self.thresholds()).__name__} (from thresholds()); got {type(thresholds).__name__}")
        for name, value in zip(thresholds._fields, thresholds):
            if name == "sigma_px" or isinstance(value, jax.core.Tracer):
                continue
            host = np.asarray(value)
            if not np.issubdtype(host.dtype, np.number) or not np.isfinite(host).all():
                raise ValueError(f"thresholds.{name} must be finite real numbers; got {value!r}")

    def check_scene(self, mask, where: str) -> None:
        """Raise ``ValueError`` (naming ``where``) for a scene, ``mask (M, P)`` bool on the
        host, that this method cannot handle; called for every scene before any work.
        Default: every scene is fine."""

    def replace(self, **changes) -> "Method":
        """A copy with ``changes`` applied (checked like a new instance)."""
        return dataclasses.replace(self, **changes)

    def table_bytes(self, num_views: int, itemsize: int) -> float:
        """Bytes per pair of nodes (``N²``, ``N = M·P``) at the peak of one scene, for the
        memory estimate (ALGORITHM.md §14). Default: the epipolar table and a masked copy
        (floats), an affinity table (a float) and a few bool tables."""
        return 3.0 * itemsize + 5.0

    @property
    def name(self) -> str:
        """The registered name this method was made from, else its class name."""
        return registered_name(self) or type(self).__name__


_REGISTRY: dict[str, Callable[[], Method]] = {}


def register_method(name: str, factory: Callable[[], Method]) -> None:
    """Make ``factory()`` available by ``name`` to every entry point and command
    (``method="name"``, ``cdog-jax associate --method name``,
    ``cdog-jax benchmark --methods name``). Re-registering a name replaces it."""
    if not isinstance(name, str) or not name or any(c in name for c in "/, "):
        raise ValueError(f"register_method: name must be a non-empty string without '/', ',' or spaces; got {name!r}")
    if not callable(factory):
        raise TypeError(f"register_method: factory must be callable; got {type(factory).__name__}")
    _REGISTRY[name] = factory


def unregister_method(name: str) -> None:
    """Remove ``name`` from the registry (``KeyError`` if it is not there)."""
    del _REGISTRY[name]


def method_names() -> tuple[str, ...]:
    """The registered names, in registration order."""
    return tuple(_REGISTRY)


def registered_name(method: Method) -> str | None:
    """The first registered name whose factory makes a method equal to ``method``."""
    for name, factory in _REGISTRY.items():
        if factory() == method:
            return name
    return None


def method_from(method, where: str) -> Method:
    """``method`` itself, or the registered method it names; a clear error otherwise."""
    if isinstance(method, Method):
        return method
    if isinstance(method, str):
        if method not in _REGISTRY:
            raise ValueError(f"{where}: unknown method {method!r}; registered: {', '.join(_REGISTRY)}")
        made = _REGISTRY[method]()
        if not isinstance(made, Method):
            raise TypeError(f"{where}: the factory registered as {method!r} made a {type(made).__name__}, not a Method")
        return made
    raise TypeError(f"{where}: method must be a Method or a registered name ({', '.join(_REGISTRY)}); got {type(method).__name__}")


def method_argument(method, config, where: str, default: str | None = "best") -> Method:
    """The method of a call: ``method`` (a :class:`Method` or a registered name), or the
    older keyword ``config`` (the same thing), not both; ``default`` when neither is given
    (``None``: one is required)."""
    if config is not None:
        if method is not None:
            raise TypeError(f"{where}: give method= or config= (its older name), not both")
        method = config
    if method is None:
        if default is None:
            raise TypeError(f"{where}: method= is required (a Method or a registered name)")
        method = default
    return method_from(method, where)
