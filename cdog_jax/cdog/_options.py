"""From the stages' declarations to one table of options (docs/ARCHITECTURE.md, "How to add
a stage"): every option's name, owner, default, kind and check, read once from the stage
list: ``Config``'s written fields are checked against it, and the ``Thresholds`` type and
the ranges of the numbers are derived from it.

A declaration is a stage (``cdog_jax/cdog/_stage.py``) or an :class:`~cdog_jax.cdog._config.OptionGroup`:
its ``when`` may be a :class:`~cdog_jax.cdog._config.Switch` (a ``bool`` option), the fields of
its ``options`` ``NamedTuple`` are structural options (``Literal[...]``: one of the listed
strings; ``bool``; ``int``: a positive int), and its ``numbers`` are traced. A stage whose
options are made from the config (``options_from``) declares no fields through them.
"""

from __future__ import annotations

import typing
from collections.abc import Callable
from typing import Literal, NamedTuple

import jax
import numpy as np

from .._types import Array, Float
from ._config import AtLeast, Range, Switch, Threshold, ThresholdsBase, check_number

STRUCTURAL, NUMERIC = "structural", "numeric"


class OptionSpec(NamedTuple):
    """One option: its name, the stage that declares it, default, kind (:data:`STRUCTURAL`:
    part of the jit key; :data:`NUMERIC`: traced), its Python type (for ``Config``'s field),
    its check ``check(value, where)`` and a description for the docs."""

    name: str
    owner: str
    default: object
    kind: str
    type: object
    check: Callable[[object, str], None]
    doc: str
    range: Range | None = None
    unit: str = ""


def _check_choice(name: str, allowed: tuple):
    def check(value, where: str) -> None:
        if value not in allowed:
            raise ValueError(f"{where}.{name} must be one of {allowed}; got {value!r}")

    return check


def _check_bool(name: str):
    def check(value, where: str) -> None:
        if not isinstance(value, bool):
            raise TypeError(f"{where}.{name} must be True or False; got {value!r}")

    return check


def _check_positive_int(name: str, low: int = 1):
    def check(value, where: str) -> None:
        if not isinstance(value, int) or isinstance(value, bool) or value < low:
            described = "a positive int" if low == 1 else f"an int >= {low}"
            raise ValueError(f"{where}.{name} must be {described}; got {value!r}")

    return check


def _check_range(name: str, allowed: Range):
    return lambda value, where: check_number(value, name, where, allowed)


def _structural(name: str, owner: str, hint, default) -> OptionSpec:
    if typing.get_origin(hint) is Literal:
        allowed = typing.get_args(hint)
        check, described = _check_choice(name, allowed), " | ".join(repr(a) for a in allowed)
    elif hint is bool:
        check, described = _check_bool(name), "bool"
    elif hint is int:
        check, described = _check_positive_int(name), "positive int"
    elif typing.get_origin(hint) is typing.Annotated and typing.get_args(hint)[0] is int:
        low = next(m.low for m in typing.get_args(hint)[1:] if isinstance(m, AtLeast))
        check, described, hint = _check_positive_int(name, low), f"int >= {low}", int
    else:
        raise TypeError(
            f"stage {owner!r}: option {name} has type {hint!r}; use a Literal, bool or int (or a Threshold)"
        )
    check(default, f"stage {owner!r} default")
    return OptionSpec(name, owner, default, STRUCTURAL, hint, check, described)


def _numeric(number: Threshold, owner: str) -> OptionSpec:
    check = _check_range(number.name, number.range)
    check(number.default, f"stage {owner!r} default")
    return OptionSpec(
        number.name,
        owner,
        number.default,
        NUMERIC,
        float,
        check,
        number.doc,
        number.range,
        number.unit,
    )


def _declared(group) -> list[OptionSpec]:
    specs = []
    when = getattr(group, "when", None)
    if isinstance(when, Switch):
        specs.append(
            OptionSpec(
                when.name,
                group.name,
                when.default,
                STRUCTURAL,
                bool,
                _check_bool(when.name),
                f"bool. {when.doc}".strip(" ."),
            )
        )
    if group.options is not None and getattr(group, "options_from", None) is None:
        hints = typing.get_type_hints(group.options, include_extras=True)
        for name in group.options._fields:
            if name not in group.options._field_defaults:
                raise TypeError(
                    f"stage {group.name!r}: option {name} of {group.options.__name__} needs a default"
                )
            specs.append(
                _structural(name, group.name, hints[name], group.options._field_defaults[name])
            )
    specs.extend(_numeric(number, group.name) for number in group.thresholds)
    return specs


def declared_options(groups) -> dict[str, OptionSpec]:
    """Every option the declarations ``groups`` make, structural ones first, each kind in
    the order of ``groups``. A stage listed twice (the same declaration, e.g. a repeated
    fit) declares its options once; two different declarations of one name are refused."""
    found: dict[str, OptionSpec] = {}
    declarer: dict[str, tuple] = {}
    for group in groups:
        declaration = (getattr(group, "run", None), group.options, group.thresholds)
        for spec in _declared(group):
            if spec.name not in found:
                found[spec.name], declarer[spec.name] = spec, declaration
            elif declarer[spec.name] != declaration:
                raise TypeError(
                    f"option {spec.name!r} is declared twice: by stage {found[spec.name].owner!r} and by stage {spec.owner!r}"
                )
    ordered = [s for s in found.values() if s.kind == STRUCTURAL] + [
        s for s in found.values() if s.kind == NUMERIC
    ]
    return {spec.name: spec for spec in ordered}


SIGMA = OptionSpec(
    "sigma_px",
    "scene",
    0.0,
    NUMERIC,
    float,
    _check_range("sigma_px", Range()),
    "2D noise std (pixels); set per scene, ignored when σ is estimated (sigma_mode 'auto' or 'robust')",
    Range(),
    "px",
)


def make_thresholds_type(
    specs: dict[str, OptionSpec], module: str, name: str = "Thresholds"
) -> type:
    """The traced ``NamedTuple`` of the numbers of ``specs``, ``sigma_px`` first, a subclass
    of :class:`~cdog_jax.cdog._config.ThresholdsBase`, documented field by field; ``module`` is where it
    is published (for pickling)."""
    numbers = [SIGMA] + [s for s in specs.values() if s.kind == NUMERIC]
    fields = typing.NamedTuple(f"_{name}Fields", [(s.name, Float[Array, ""]) for s in numbers])
    lines = [f"    {s.name} ({s.owner}): {s.doc}" for s in numbers]
    doc = (
        "Numeric thresholds, traced (scalars, or arrays with a leading batch axis under vmap).\n\n"
        "``tau_px = max(alpha_tau * sqrt(2) * sigma_px, tau_min_px)`` (docs/ALGORITHM.md §1–2).\n"
        "Each field, with the stage that reads it:\n\n" + "\n".join(lines)
    )
    return type(
        name, (fields, ThresholdsBase), {"__slots__": (), "__doc__": doc, "__module__": module}
    )


def units(specs: dict[str, OptionSpec]) -> dict[str, str]:
    """The unit of every number (``sigma_px`` included): ``"px"``, ``"px2"`` or ``""``."""
    return {SIGMA.name: SIGMA.unit, **{s.name: s.unit for s in specs.values() if s.kind == NUMERIC}}


def ranges(specs: dict[str, OptionSpec]) -> dict[str, Range]:
    """The allowed range of every number (``sigma_px`` included)."""
    return {
        SIGMA.name: SIGMA.range,
        **{s.name: s.range for s in specs.values() if s.kind == NUMERIC},
    }


def check_thresholds(
    thresholds, kind: type, allowed: dict[str, Range], *, skip: tuple[str, ...] = ("sigma_px",)
) -> None:
    """Raise if a concrete value of ``thresholds`` (scalars or arrays) is outside its range; names
    the field, the value and, for arrays, the index. Traced values are not checked."""
    if not isinstance(thresholds, kind):
        raise TypeError(
            f"thresholds must be a {kind.__name__} (from Config.thresholds()); got {type(thresholds).__name__}"
        )
    for name, value in zip(thresholds._fields, thresholds):
        if name in skip or isinstance(value, jax.core.Tracer):
            continue
        host = np.asarray(value)
        if host.dtype == np.bool_ or not (
            np.issubdtype(host.dtype, np.floating) or np.issubdtype(host.dtype, np.integer)
        ):
            raise TypeError(f"thresholds.{name} must be real numbers; got dtype {host.dtype}")
        ok = allowed[name].ok(host)
        if not ok.all():
            where = tuple(int(i) for i in np.argwhere(~ok)[0])
            at = f" at index {where}" if where else ""
            raise ValueError(
                f"thresholds.{name} must be {allowed[name].describe()}; got {host[where].item()!r}{at}"
            )


def describe(specs: dict[str, OptionSpec], groups) -> str:
    """A docstring section: each option, under the stage that declares it (with the first
    sentence of the stage's options docstring)."""
    lines = []
    for group in groups:
        own = [s for s in specs.values() if s.owner == group.name]
        if not own:
            continue
        declares = group.options is not None and getattr(group, "options_from", None) is None
        summary = (
            " ".join((group.options.__doc__ or "").split()).split(". ")[0].rstrip(".")
            if declares
            else ""
        )
        lines.append(f"    {group.name}: {summary}" if summary else f"    {group.name}:")
        for s in own:
            kind = "traced" if s.kind == NUMERIC else "static"
            lines.append(f"        {s.name} = {s.default!r} ({kind}): {s.doc}")
    return "\n".join(lines)
