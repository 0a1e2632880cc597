"""Optional nonlinear refinement of each group's 3D point (docs/ALGORITHM.md §10, ALGORITHM.md §10).

Levenberg–Marquardt (optimistix) on the member reprojection residuals in pixels, started
from the DLT point, vmapped over groups; a refined point replaces the DLT point only where
it lowers the group's BPE, so refinement never makes a group worse. A group whose solver
stopped at ``max_steps`` is reported (``Status.REFINE_CAPPED``).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from .._expect import ARRAY, INT, expect_args
from .._status import Status
from .._types import Array, Bool, Float
from ..cdog._config import Switch
from ..cdog._stage import Scene, Stage, State
from ..geometry._camera import Rig
from ..geometry._projection import project


def _residuals(X, args):
    rig, xy, member = args
    xy_hat, _ = project(rig, X)  # (M, 2)
    return jnp.where(member[:, None], xy_hat - xy, 0.0).reshape(-1)


def refine_points(
    rig: Rig,
    X0: Float[Array, "G 3"],
    xy_g: Float[Array, "G M 2"],
    member: Bool[Array, "G M"],
    max_steps: int,
) -> tuple[Float[Array, "G 3"], Bool[Array, ""]]:
    """Refined points ``(G, 3)`` (scene units) from ``X0 (G, 3)``, ``xy_g (G, M, 2)`` and
    ``member (G, M)``; groups with < 2 members are unchanged. Also ``()`` True when the
    solver of some group (of ≥ 2 members) stopped at ``max_steps`` before converging."""
    expect_args(
        "refine_points",
        rig=(rig, Rig),
        X0=(X0, ARRAY),
        xy_g=(xy_g, ARRAY),
        member=(member, ARRAY),
        max_steps=(max_steps, INT),
    )
    import optimistix as optx  # here, not at import: only refinement needs it (a large import)

    dtype = X0.dtype
    # optimistix's damping and step sizes take JAX's default float: with 64-bit JAX on, a
    # float32 problem meets float64 damping and lineax refuses the mixed structures. Such a
    # problem is solved in the default float, its points returned in their own dtype.
    default = jnp.dtype(jnp.result_type(float))  # float64 with 64-bit JAX on
    work = default if jnp.finfo(default).bits > jnp.finfo(dtype).bits else dtype
    if work != dtype:
        rig, X0, xy_g = jax.tree.map(
            lambda a: a.astype(work) if jnp.issubdtype(a.dtype, jnp.floating) else a,
            (rig, X0, xy_g),
        )
    solver = optx.LevenbergMarquardt(rtol=1e-6, atol=1e-6)

    def one(X, xy, mem):
        sol = optx.least_squares(
            _residuals, solver, X, args=(rig, xy, mem), max_steps=max_steps, throw=False
        )
        r0 = _residuals(X, (rig, xy, mem))
        r1 = _residuals(sol.value, (rig, xy, mem))
        better = jnp.all(jnp.isfinite(sol.value)) & (jnp.sum(r1 * r1) < jnp.sum(r0 * r0))
        used = jnp.sum(mem, dtype=jnp.int32) >= 2
        # Not successful after max_steps steps (the result's enumeration is a promoted one,
        # so its max_steps item does not compare equal to optx.RESULTS.max_steps_reached).
        stopped = (sol.stats["num_steps"] >= max_steps) & ~(sol.result == optx.RESULTS.successful)
        capped = used & stopped
        return jnp.where(better & used, sol.value, X), capped

    X, capped = jax.vmap(one)(X0, xy_g, member)
    return X.astype(dtype), jnp.any(capped)


class RefineOptions(NamedTuple):
    """The solver's step bound."""

    refine_max_steps: int = 20


def refine_stage(scene: Scene, state: State, options: RefineOptions) -> State:
    """Each fitted point refined by Levenberg–Marquardt (``Status.REFINE_CAPPED`` at the bound)."""
    fit = state.fit
    X, capped = refine_points(scene.rig, fit.X, fit.xy_g, fit.member, options.refine_max_steps)
    return state._replace(fit=fit._replace(X=X)).flag(capped, Status.REFINE_CAPPED)


REFINE = Stage(
    "refine",
    refine_stage,
    RefineOptions,
    Switch("refine", False, "refine each point by Levenberg–Marquardt"),
)
