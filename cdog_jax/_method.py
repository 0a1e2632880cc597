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

**Methods that only decide the groups** (:class:`GroupTableMethod`): the shared σ, gate,
triangulation and validity gate around a group-table function (docs/ARCHITECTURE.md, "How
to add a method").

A subclass of :class:`GroupTableMethod` is a frozen dataclass whose ``float`` fields are its
numbers (traced) and whose other fields are its structure (static), and which implements
:meth:`GroupTableMethod.group_table`. Everything else is shared, so that every such method
is compared on equal terms with C-DOG: the noise σ (given, or estimated from the epipolar
distances as C-DOG does), the σ-matched epipolar gate ``τ = max(alpha_tau·√2·σ,
tau_min_px)``, the multi-view DLT point of each group, and the validity gate
(ALGORITHM.md §12) before the :class:`~cdog_jax.Association` is built.

**Group-table methods on the host** (:class:`HostGroupTableMethod`): NumPy or SciPy per
scene, never jitted. A :class:`HostGroupTableMethod` implements :meth:`HostGroupTableMethod.host_groups` on
NumPy arrays; everything around it is shared with every :class:`GroupTableMethod` (σ, the
σ-matched gate, the DLT point and the validity gate, each jitted once), so that a host
method is compared on the same terms as a jitted one. :func:`cdog_jax.associate` runs such
a method scene by scene; :func:`cdog_jax.benchmark.sweep_host` scores it on the benchmark.
"""

from __future__ import annotations

import abc
import dataclasses
from collections.abc import Callable
from functools import partial
from typing import ClassVar, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._result import Association, association_from_groups
from ._runtime.xla_kernels import jit
from ._status import Status
from ._types import Array, Bool, Float, Int
from .cdog._stage import raise_flag
from .geometry._camera import Rig
from .geometry._epipolar import epipolar_distances
from .geometry._projection import group_errors
from .geometry._triangulate import triangulate_views_last
from .graph._groups import gather_groups
from .graph._sigma import estimate_sigma, focal_scale
from .graph._sigma_robust import estimate_sigma_robust
from .refine._validity import ambiguous_groups, validity_gate


class Observations(NamedTuple):
    """One scene's detections, a pytree: ``xy (M, P, 2)`` pixels, ``mask (M, P)`` bool (the
    slot holds a detection; other slots may hold anything), and optional ``weights (M, P)``
    (non-negative confidences of the members' triangulation equations; ``None``: all 1)."""

    xy: Float[Array, "M P 2"]
    mask: Bool[Array, "M P"]
    weights: Float[Array, "M P"] | None = None


def finite_observations(
    xy: Float[Array, "M P 2"], mask: Bool[Array, "M P"]
) -> tuple[Float[Array, "M P 2"], Bool[Array, "M P"], Bool[Array, ""]]:
    """``(xy, mask, dropped)``: a detection that is not finite (NaN or inf) left out (its slot
    becomes padding holding 0), and whether a valid slot held one. Inside a compiled program
    nothing can be refused; one such detection would otherwise spread through every table it
    enters (a NaN distance undoes other groups) and go unsaid."""
    finite = jnp.all(jnp.isfinite(xy), axis=-1)
    dropped = jnp.any(mask & ~finite)
    return jnp.where(finite[..., None], xy, 0.0), mask & finite, dropped


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
    def structure(self) -> Method:
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
            raise TypeError(
                f"thresholds must be a {type(self.thresholds()).__name__} (from thresholds()); got {type(thresholds).__name__}"
            )
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

    def replace(self, **changes) -> Method:
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
        raise ValueError(
            f"register_method: name must be a non-empty string without '/', ',' or spaces; got {name!r}"
        )
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
            raise ValueError(
                f"{where}: unknown method {method!r}; registered: {', '.join(_REGISTRY)}"
            )
        made = _REGISTRY[method]()
        if not isinstance(made, Method):
            raise TypeError(
                f"{where}: the factory registered as {method!r} made a {type(made).__name__}, not a Method"
            )
        return made
    raise TypeError(
        f"{where}: method must be a Method or a registered name ({', '.join(_REGISTRY)}); got {type(method).__name__}"
    )


def method_argument(method, where: str, default: str | None = "best") -> Method:
    """The method of a call: ``method`` (a :class:`Method` or a registered name);
    ``default`` when it is not given (``None``: one is required)."""
    if method is None:
        if default is None:
            raise TypeError(f"{where}: method= is required (a Method or a registered name)")
        method = default
    return method_from(method, where)


# --------------------------------------------------------------------------- group-table methods

SIGMA_MODES = ("given", "auto", "robust")
"""Where a group-table method's σ comes from: the caller, or C-DOG's two estimators."""

_THRESHOLD_TYPES: dict[type, type] = {}


def _numeric_fields(cls: type) -> tuple[str, ...]:
    return tuple(f.name for f in dataclasses.fields(cls) if f.type in ("float", float))


def thresholds_type(cls: type) -> type:
    """The ``NamedTuple`` of ``cls``'s numbers: ``sigma_px`` then its ``float`` fields (one
    type per class, made once)."""
    if cls not in _THRESHOLD_TYPES:
        fields = [("sigma_px", Float[Array, ""])] + [
            (name, Float[Array, ""]) for name in _numeric_fields(cls)
        ]
        _THRESHOLD_TYPES[cls] = NamedTuple(f"{cls.__name__}Thresholds", fields)
    return _THRESHOLD_TYPES[cls]


@dataclasses.dataclass(frozen=True)
class GroupTableMethod(Method):
    """A method that makes the group table from the scene's epipolar distances.

    Shared fields: ``sigma_mode`` (``"given"``, ``"auto"`` or ``"robust"``: σ from the
    scene's epipolar distances by C-DOG's estimators, ALGORITHM.md §0.1–0.2), the gate ``alpha_tau`` and
    ``tau_min_px`` (px), and the validity gate's ``min_parallax_deg`` and ``max_err_frac``
    (as in :class:`cdog_jax.Config`).
    """

    sigma_mode: str = "given"
    alpha_tau: float = 2.0
    tau_min_px: float = 1.0
    min_parallax_deg: float = 1.0
    max_err_frac: float = 3.0

    def __post_init__(self):
        if self.sigma_mode not in SIGMA_MODES:
            raise ValueError(
                f"{type(self).__name__}.sigma_mode must be one of {SIGMA_MODES}; got {self.sigma_mode!r}"
            )
        for name in _numeric_fields(type(self)):
            value = getattr(self, name)
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, float))
                or not np.isfinite(value)
                or value < 0
            ):
                raise ValueError(
                    f"{type(self).__name__}.{name} must be a finite number >= 0; got {value!r}"
                )
        later = getattr(super(), "__post_init__", None)  # an options base class's own checks
        if later is not None:
            later()

    #: A baseline written as a plain function ``f(rig, xy, mask, d, tau, sigma, thresholds, options)``
    #: (``thresholds``: ``{name: traced value}`` for the names in its ``THRESHOLDS``; ``options``: this
    #: method) sets it instead of overriding :meth:`group_table`.
    GROUPS: ClassVar[Callable | None] = None

    def group_table(
        self,
        rig: Rig,
        xy: Float[Array, "M P 2"],
        mask: Bool[Array, "M P"],
        d: Float[Array, "M P M P"],
        sigma: Float[Array, ""],
        tau: Float[Array, ""],
        thresholds: tuple,
    ) -> tuple[Int[Array, "G M"], Bool[Array, " G"], Int[Array, ""]]:
        """``groups (G, M)`` (slot per view or -1; ``G = M·P // 2``), ``valid (G,)`` and an
        int32 status. ``xy`` has its padding zeroed; ``d[m, i, n, j]`` is the distance (px)
        in image n from detection ``(n, j)`` to the epipolar line of ``(m, i)`` (``+inf``
        within a view and for padding); ``tau`` is the σ-matched gate (px). A valid group
        has ≥ 2 members, at most one per view, and groups are disjoint."""
        if self.GROUPS is None:
            raise NotImplementedError(
                f"{type(self).__name__} must override group_table or set GROUPS"
            )
        by_name = {name: getattr(thresholds, name) for name in getattr(self, "THRESHOLDS", ())}
        return type(self).GROUPS(rig, xy, mask, d, tau, sigma, by_name, self)

    def structure(self) -> GroupTableMethod:
        defaults = type(self)()
        return dataclasses.replace(
            self, **{name: getattr(defaults, name) for name in _numeric_fields(type(self))}
        )

    def thresholds(self, sigma_px=0.0, *, dtype=None) -> tuple:
        dtype = np.dtype(jax.dtypes.canonicalize_dtype(dtype or jnp.float32))
        sigma = (
            jnp.asarray(sigma_px, dtype)
            if isinstance(sigma_px, jax.Array)
            else np.asarray(sigma_px, dtype)
        )
        values = {
            name: np.asarray(getattr(self, name), dtype) for name in _numeric_fields(type(self))
        }
        return thresholds_type(type(self))(sigma_px=sigma, **values)

    def associate_scene(
        self, rig: Rig, observations: Observations, thresholds: tuple
    ) -> Association:
        thresholds = type(thresholds)(*(jnp.asarray(v) for v in thresholds))
        xy, mask, dropped = finite_observations(observations.xy, observations.mask)
        observations = observations._replace(xy=xy, mask=mask)
        xy, d, sigma, tau, fallback = scene_gate(rig, observations, thresholds, self.sigma_mode)
        groups, valid, status = self.group_table(
            rig, xy, observations.mask, d, sigma, tau, thresholds
        )
        return finish_table(
            rig,
            xy,
            d,
            groups,
            valid,
            status
            | raise_flag(fallback, Status.SIGMA_FALLBACK)
            | raise_flag(dropped, Status.NONFINITE_DETECTION),
            sigma,
            tau,
            thresholds,
        )


def scene_gate(
    rig: Rig, observations: Observations, thresholds: tuple, sigma_mode: str
) -> tuple[
    Float[Array, "M P 2"],
    Float[Array, "M P M P"],
    Float[Array, ""],
    Float[Array, ""],
    Bool[Array, ""],
]:
    """What every group-table method starts from: ``xy (M, P, 2)`` with padding zeroed, the
    epipolar distances ``d (M, P, M, P)`` (px), σ (given, or estimated when ``sigma_mode``
    is ``"auto"`` or ``"robust"``), the σ-matched gate τ (px) and whether the estimate fell back."""
    mask = observations.mask
    xy = jnp.where(mask[..., None], observations.xy, 0.0)
    d = epipolar_distances(rig, xy, mask)
    if sigma_mode == "auto":
        sigma, fallback = estimate_sigma(d, mask, focal_scale(rig.K))
    elif sigma_mode == "robust":
        sigma, fallback = estimate_sigma_robust(d, mask, focal_scale(rig.K))
    else:
        sigma, fallback = thresholds.sigma_px, jnp.asarray(False)
    tau = jnp.maximum(thresholds.alpha_tau * jnp.sqrt(2.0) * sigma, thresholds.tau_min_px)
    return xy, d, sigma, tau, fallback


def finish_table(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    d: Float[Array, "M P M P"],
    groups: Int[Array, "G M"],
    valid: Bool[Array, " G"],
    status: Int[Array, ""],
    sigma: Float[Array, ""],
    tau: Float[Array, ""],
    thresholds: tuple,
) -> Association:
    """The :class:`~cdog_jax.Association` of a group table ``(G, M)``: every valid group's
    multi-view DLT point, the validity gate (with ``thresholds.max_err_frac`` and
    ``thresholds.min_parallax_deg``, and rule 5: a degenerate group with a rival is dissolved,
    raising :attr:`Status.AMBIGUOUS_GEOMETRY`), its errors; ``xy (M, P, 2)`` pixels (padding
    zeroed), ``d (M, P, M, P)`` their epipolar distances (px)."""
    P = xy.shape[1]
    member = valid[:, None] & (groups >= 0)
    xy_g = gather_groups(groups, xy)
    X, _ = triangulate_views_last(rig, xy_g, member)
    member, valid, X = validity_gate(
        rig, xy_g, member, X, tau, thresholds.max_err_frac, thresholds.min_parallax_deg
    )
    ambiguous = valid & ambiguous_groups(rig, d, groups, member, X, tau)
    valid = valid & ~ambiguous
    member = member & valid[:, None]
    bpe, err_px = group_errors(rig, X, xy_g, member)
    return association_from_groups(
        groups,
        valid,
        member,
        X,
        bpe,
        err_px,
        P,
        jnp.asarray(sigma, xy.dtype),
        jnp.asarray(tau, xy.dtype),
        status | raise_flag(jnp.any(ambiguous), Status.AMBIGUOUS_GEOMETRY),
    )


# --------------------------------------------------------------------------- on the host


@partial(jit, static_argnames=("sigma_mode",))
def _gate(rig, observations, thresholds, sigma_mode):
    return scene_gate(rig, observations, thresholds, sigma_mode)


_finish = jit(finish_table)


@dataclasses.dataclass(frozen=True)
class HostGroupTableMethod(GroupTableMethod):
    """A group-table method whose grouping runs on the host (``jittable = False``).

    Subclasses set ``HOST_NAME`` (its registered name, for messages) and ``HOST_TOOLS`` (what
    it runs on, e.g. ``"NumPy, scipy.optimize.milp"``), implement :meth:`host_groups`, and may
    override :meth:`check_scene` to refuse scenes they cannot handle."""

    jittable: ClassVar[bool] = False
    HOST_NAME: ClassVar[str] = "host method"
    HOST_TOOLS: ClassVar[str] = "NumPy"

    def check_scene(self, mask, where: str) -> None:
        """Raise ``ValueError`` naming ``where`` for a scene this method does not take
        (``mask (M, P)`` bool, host array). Every scene by default."""

    def host_groups(
        self,
        rig: Rig,
        xy: np.ndarray,
        mask: np.ndarray,
        d: np.ndarray,
        tau: float,
        thresholds: tuple,
    ) -> tuple[np.ndarray, np.ndarray]:
        """``groups (G, M)`` int (slot per view or -1; ``G = M·P // 2``) and ``valid (G,)``
        bool from host arrays: ``xy (M, P, 2)`` px (padding zeroed), ``mask (M, P)``, the
        epipolar distances ``d (M, P, M, P)`` px, the gate ``tau`` px and the method's
        numbers ``thresholds`` (host scalars)."""
        raise NotImplementedError(f"{type(self).__name__} must implement host_groups")

    def group_table(self, rig, xy, mask, d, sigma, tau, thresholds):
        raise TypeError(
            f"{self.HOST_NAME}: a host method; it has no traced group table (call associate_scene on host arrays)"
        )

    def associate_scene(
        self, rig: Rig, observations: Observations, thresholds: tuple
    ) -> Association:
        if any(
            isinstance(leaf, jax.core.Tracer)
            for leaf in jax.tree.leaves((rig, observations, thresholds))
        ):
            raise TypeError(
                f"{self.HOST_NAME}: a host method ({self.HOST_TOOLS}); it cannot run under jit or vmap"
            )
        mask = np.asarray(observations.mask, bool)
        self.check_scene(mask, self.HOST_NAME)
        observations = Observations(observations.xy, observations.mask)
        xy, d, sigma, tau, fallback = _gate(rig, observations, thresholds, self.sigma_mode)
        groups, valid = self.host_groups(
            rig, np.asarray(xy), mask, np.asarray(d), float(tau), thresholds
        )
        status = raise_flag(fallback, Status.SIGMA_FALLBACK)
        return _finish(rig, xy, d, groups, valid, status, sigma, tau, thresholds)
