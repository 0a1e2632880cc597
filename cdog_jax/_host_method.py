"""Group-table methods that run on the host: NumPy or SciPy per scene, never jitted.

A :class:`HostGroupTableMethod` implements :meth:`HostGroupTableMethod.host_groups` on
NumPy arrays; everything around it is shared with every :class:`GroupTableMethod` (σ, the
σ-matched gate, the DLT point and the validity gate, each jitted once), so that a host
method is compared on the same terms as a jitted one. :func:`cdog_jax.associate` runs such
a method scene by scene; :func:`cdog_jax.benchmark.sweep_host` scores it on the benchmark.
"""

from __future__ import annotations

import dataclasses
from functools import partial
from typing import ClassVar

import jax
import numpy as np

from ._method import Observations
from ._result import Association
from .cdog._stage import raise_flag
from ._status import Status
from ._table_method import GroupTableMethod, finish_table, scene_gate
from .geometry._camera import Rig


@partial(jax.jit, static_argnames=("sigma_mode",))
def _gate(rig, observations, th, sigma_mode):
    return scene_gate(rig, observations, th, sigma_mode)


_finish = jax.jit(finish_table)


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
        self, rig: Rig, xy: np.ndarray, mask: np.ndarray, d: np.ndarray, tau: float, thresholds: tuple
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

    def associate_scene(self, rig: Rig, observations: Observations, thresholds: tuple) -> Association:
        if any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree.leaves((rig, observations, thresholds))):
            raise TypeError(f"{self.HOST_NAME}: a host method ({self.HOST_TOOLS}); it cannot run under jit or vmap")
        mask = np.asarray(observations.mask, bool)
        self.check_scene(mask, self.HOST_NAME)
        observations = Observations(observations.xy, observations.mask)
        xy, d, sigma, tau, fallback = _gate(rig, observations, thresholds, self.sigma_mode)
        groups, valid = self.host_groups(rig, np.asarray(xy), mask, np.asarray(d), float(tau), thresholds)
        status = raise_flag(fallback, Status.SIGMA_FALLBACK)
        return _finish(rig, xy, groups, valid, status, sigma, tau, thresholds)
