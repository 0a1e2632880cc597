"""Shared test builders: a small hand-built rig, noise-free/noisy scenes with shuffled
slots, tolerances per dtype, tree comparison."""

import os
import platform
import subprocess
import sys

import jax
import jax.numpy as jnp
import jaxlib
import numpy as np

from cdog_jax import Rig
from cdog_jax._runtime import xla_kernels

# Tolerances: float32 checks in pixels / relative scene size, float64 tight.
# How the suite compiles (tests/conftest.py): XLA's older CPU code generator, LLVM without
# optimisation, and SSE4.2 code (no fused multiply-add, so every way of compiling a program
# rounds alike). A test that needs XLA's defaults removes these flags. Elsewhere than on
# x86-64, where an SSE4.2 cap means nothing, only the older generator: the suite's bitwise
# comparisons hold with it, as they did before the other two switches. Everywhere, each
# program's machine code in one piece: XLA otherwise splits it to generate the pieces on
# several threads, which costs a tenth more processor time, and the suite's workers
# already keep every core busy.
FAST_COMPILE_FLAGS = (
    (
        "--xla_cpu_use_fusion_emitters=false --xla_backend_optimization_level=0"
        " --xla_cpu_max_isa=SSE4_2"
        if platform.machine().lower() in ("x86_64", "amd64")
        else "--xla_cpu_use_fusion_emitters=false"
    )
    + " --xla_cpu_parallel_codegen_split_count=1"
) + (
    # The command line's own switch (cdog_jax/_runtime/xla_kernels.py), in the suite's
    # process too: its child processes (command-line tests) then compile what it compiles.
    f" {xla_kernels.FLAG}" if jaxlib.__version__.startswith(xla_kernels.MEASURED_JAXLIB) else ""
)


def run_with_xla_defaults(
    test_file: str, function: str, switches: str = FAST_COMPILE_FLAGS
) -> None:
    """Call ``function()`` of the test module at ``test_file`` in a child process compiled
    without the suite's ``switches`` (a space-separated list; by default all of them: XLA's
    defaults, the code users run)."""
    removed = set(switches.split())
    kept = [flag for flag in os.environ.get("XLA_FLAGS", "").split() if flag not in removed]
    env = dict(os.environ, XLA_FLAGS=" ".join(kept))
    folder, module = os.path.split(os.path.splitext(os.path.abspath(test_file))[0])
    tests = os.path.dirname(os.path.abspath(__file__))
    code = f"import sys; sys.path[:0] = [{tests!r}, {folder!r}]; import {module}; {module}.{function}()"
    subprocess.run([sys.executable, "-c", code], env=env, check=True)


TOL = {
    "float32": {"px": 2e-2, "rel": 1e-4},
    "float64": {"px": 1e-8, "rel": 1e-10},
}


def look_at(center, target=(0.0, 0.0, 0.0), up=(0.0, 0.0, 1.0)):
    """World→camera ``R, t`` of a camera at ``center`` looking at ``target``."""
    c = np.asarray(center, float)
    z = np.asarray(target, float) - c
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, float))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ c


def ring_rig(num_views=5, radius=3.0, negate=(), seed=0, dtype=np.float32):
    """Cameras on a ring around the origin, 640×480, f = 800 px; views in ``negate`` get
    ``K → −K`` (``K[2,2] = −1``, same projection)."""
    rng = np.random.default_rng(seed)
    Ks, Rs, ts = [], [], []
    for m in range(num_views):
        ang = 2 * np.pi * m / num_views + 0.2 * rng.standard_normal()
        c = np.array(
            [radius * np.cos(ang), radius * np.sin(ang), 1.0 + 0.5 * rng.standard_normal()]
        )
        R, t = look_at(c, target=0.1 * rng.standard_normal(3))
        K = np.array(
            [
                [800.0 + 20 * m, 0.5, 320.0 + 3 * m],
                [0.0, 790.0 + 20 * m, 240.0 - 2 * m],
                [0.0, 0.0, 1.0],
            ]
        )
        if m in negate:
            K = -K
        Ks.append(K)
        Rs.append(R)
        ts.append(t)
    return Rig(
        jnp.asarray(np.array(Ks), dtype),
        jnp.asarray(np.array(Rs), dtype),
        jnp.asarray(np.array(ts), dtype),
    )


def project_np(rig, X):
    """Pixels ``(M, n, 2)`` and in-front-and-inside flags ``(M, n)`` in NumPy float64."""
    K, R, t = (np.asarray(a, np.float64) for a in (rig.K, rig.R, rig.t))
    X_cam = np.einsum("mij,nj->mni", R, X) + t[:, None, :]
    h = np.einsum("mij,mnj->mni", K, X_cam)
    xy = h[..., :2] / h[..., 2:3]
    inside = (xy[..., 0] >= 0) & (xy[..., 0] < 640) & (xy[..., 1] >= 0) & (xy[..., 1] < 480)
    return xy, (X_cam[..., 2] > 0) & inside


def random_scene(rig, num_points, capacity, sigma=0.0, seed=0, box=0.6, clutter=0, garbage=0.0):
    """Uniform points in ``[-box, box]³`` seen by ≥ 2 views, noisy, slots shuffled per view.

    Returns ``xy (M, P, 2)``, ``mask (M, P)``, ``instance (M, P)`` (-1: padding/clutter) and
    ``X (n, 3)``. Padded slots hold ``garbage`` (0 by default).
    """
    rng = np.random.default_rng(seed)
    M = rig.K.shape[0]
    X = np.zeros((0, 3))
    while len(X) < num_points:
        cand = rng.uniform(-box, box, (4 * num_points + 4, 3))
        _, vis = project_np(rig, cand)
        X = np.concatenate([X, cand[vis.sum(0) >= 2]])
    X = X[:num_points]
    xy_true, vis = project_np(rig, X)
    xy = np.full((M, capacity, 2), garbage, np.float64)
    mask = np.zeros((M, capacity), bool)
    inst = np.full((M, capacity), -1)
    for m in range(M):
        ids = np.flatnonzero(vis[m])
        n_clutter = clutter
        if len(ids) + n_clutter > capacity:
            raise ValueError("capacity too small")
        slots = rng.permutation(capacity)[: len(ids) + n_clutter]
        xy[m, slots[: len(ids)]] = xy_true[m, ids] + sigma * rng.standard_normal((len(ids), 2))
        inst[m, slots[: len(ids)]] = ids
        xy[m, slots[len(ids) :]] = rng.uniform([0, 0], [640, 480], (n_clutter, 2))
        mask[m, slots] = True
    return xy, mask, inst, X


def tree_allclose(a, b, rtol=1e-6, atol=1e-6):
    la, lb = jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)
    return len(la) == len(lb) and all(
        np.shape(x) == np.shape(y)
        and np.allclose(np.asarray(x), np.asarray(y), rtol=rtol, atol=atol)
        for x, y in zip(la, lb)
    )


def purity(labels, instance, mask):
    """(number of groups, number of groups whose members share one instance, unassigned)."""
    labels = np.asarray(labels)
    groups = [g for g in np.unique(labels) if g >= 0]
    pure = sum(
        len(set(instance[labels == g])) == 1 and instance[labels == g][0] >= 0 for g in groups
    )
    return len(groups), pure, int((mask & (labels < 0)).sum())


def x64(on: bool = True):
    """Context manager: float64 enabled (``on=True``) or the default precision."""
    return jax.enable_x64(on)


def memory_mappings() -> int | None:
    """Memory mappings of this process (Linux), or None where /proc is not there."""
    try:
        with open("/proc/self/maps", "rb") as f:
            return sum(1 for _ in f)
    except OSError:
        return None
