"""``sigma="auto"``: the 2D noise level from the epipolar nearest-neighbour distances
(ALGORITHM.md §0.1).

The smallest epipolar distance of a node into another view is either its true match
(half-normal: both points' noise, scale ``√2 σ``) or the nearest unrelated point (roughly
exponential for points scattered over the image). A fixed number of EM iterations fits
that two-component mixture; ``σ = c / √2`` from the half-normal scale ``c``.
"""

import jax
import jax.numpy as jnp

from .._types import Array, Bool, Float

EM_ITERS = 30


def estimate_sigma(d: Float[Array, "M P M P"], mask: Bool[Array, "M P"]) -> Float[Array, ""]:
    """Robust noise estimate ``()`` (pixels) from the epipolar distance table
    ``d (M, P, M, P)`` and ``mask (M, P)``; 0 if nothing to fit."""
    return sigma_from_nearest(jnp.min(d, axis=-1))  # (M, P, M): nearest distance of node (m, i) into view n


def sigma_from_nearest(s: Float[Array, "*S"]) -> Float[Array, ""]:
    """The estimate from nearest epipolar distances ``s`` (pixels, any shape; ``inf``: no
    sample), e.g. those of many scenes pooled; 0 if nothing to fit."""
    ok = jnp.isfinite(s)
    w_ok = ok.astype(s.dtype)
    n = jnp.sum(w_ok)
    x = jnp.where(ok, s, 0.0)
    tiny = jnp.finfo(s.dtype).tiny

    # Start: c from the median, lambda from the mean.
    flat = jnp.where(ok, s, jnp.inf).reshape(-1)
    median = jnp.sort(flat)[jnp.maximum(n.astype(jnp.int32) - 1, 0) // 2]
    median = jnp.where(jnp.isfinite(median), median, 0.0)
    c0 = jnp.maximum(median, 1e-3)
    lam0 = 1.0 / jnp.maximum(jnp.sum(x) / jnp.maximum(n, 1.0), 1e-3)

    def em(_, state):
        c, lam, pi = state
        log_half_normal = 0.5 * jnp.log(2.0 / jnp.pi) - jnp.log(c) - 0.5 * (x / c) ** 2
        log_expo = jnp.log(lam) - lam * x
        a = jnp.log(pi) + log_half_normal
        b = jnp.log1p(-pi) + log_expo
        resp = jax.nn.sigmoid(a - b) * w_ok  # P(true match)
        n1 = jnp.sum(resp)
        n0 = n - n1
        c = jnp.sqrt(jnp.sum(resp * x * x) / jnp.maximum(n1, tiny))
        lam = n0 / jnp.maximum(jnp.sum((w_ok - resp) * x), tiny)
        pi = jnp.clip(n1 / jnp.maximum(n, 1.0), 1e-4, 1.0 - 1e-4)
        return jnp.maximum(c, 1e-6), jnp.maximum(lam, 1e-6), pi

    c, _, _ = jax.lax.fori_loop(0, EM_ITERS, em, (c0, lam0, jnp.asarray(0.5, s.dtype)))
    return jnp.where(n > 0, c / jnp.sqrt(2.0), 0.0)
