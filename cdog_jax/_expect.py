"""Type checks of public arguments: a wrong type (swapped arguments, a path where a rig is
expected) raises a ``TypeError`` that names the function, the argument, what it expected
and what it got, before any work.

Only ``isinstance`` tests, so they are cheap and hold under ``jit``/``vmap`` (a traced
array is a ``jax.Array``; a traced :class:`~cdog_jax.Rig` is still a ``Rig``).
"""

from __future__ import annotations

import numbers
import os

import jax
import numpy as np


class Kind:
    """An expected kind of argument that is not one Python type: a test and a description."""

    def __init__(self, description: str, test):
        self.description = description
        self.test = test


def _is_array_like(value) -> bool:
    if value is None or isinstance(value, (str, bytes)):
        return False
    if isinstance(value, (jax.Array, np.ndarray, np.generic, numbers.Number, list, tuple)):
        return True
    return hasattr(value, "__array__") or hasattr(value, "__jax_array__")


ARRAY = Kind("an array (jax.Array, numpy.ndarray, list or number)", _is_array_like)
PATH = Kind("a path (str or os.PathLike)", lambda v: isinstance(v, (str, os.PathLike)))
INT = Kind(
    "an int", lambda v: isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_))
)
REAL = Kind(
    "a real number",
    lambda v: (
        isinstance(v, (numbers.Real, np.floating, np.integer))
        and not isinstance(v, (bool, np.bool_))
    ),
)


def _describe_expected(expected) -> str:
    options = expected if isinstance(expected, tuple) else (expected,)
    names = [
        o.description if isinstance(o, Kind) else ("None" if o is type(None) else o.__name__)
        for o in options
    ]
    return " or ".join(names)


def _matches(value, expected) -> bool:
    options = expected if isinstance(expected, tuple) else (expected,)
    return any(o.test(value) if isinstance(o, Kind) else isinstance(value, o) for o in options)


def describe_value(value) -> str:
    """A short description of what arrived: its type, and its value when that is short."""
    name = type(value).__name__
    if isinstance(value, (str, os.PathLike, numbers.Number)) or value is None:
        text = repr(value)
        return name if value is None else f"{name} {text[:60] + '...' if len(text) > 60 else text}"
    shape = getattr(value, "shape", None)
    return (
        f"{name} of shape {tuple(shape)}"
        if shape is not None and not isinstance(value, type)
        else name
    )


def expect(value, expected, name: str, function: str) -> None:
    """Raise ``TypeError`` unless ``value`` is of the ``expected`` type(s) or :class:`Kind`.

    Args:
        value: the argument as passed.
        expected: a type, a :class:`Kind` (``ARRAY``, ``PATH``, ``INT``, ``REAL``) or a tuple
            of them (``type(None)`` for an optional argument).
        name: the argument's name in the signature.
        function: the public function's name, as users call it.
    """
    if not _matches(value, expected):
        raise TypeError(
            f"{function}: {name} must be {_describe_expected(expected)}; got {describe_value(value)}"
        )


def expect_args(function: str, **arguments) -> None:
    """:func:`expect` for several arguments: ``expect_args("f", rig=(rig, Rig), path=(path, PATH))``."""
    for name, (value, expected) in arguments.items():
        expect(value, expected, name, function)
