"""The ``cdog-jax`` command line (also ``python -m cdog_jax``): every command, and the
argument checks and output they share."""

from ._cli import build_parser as build_parser, main as main
