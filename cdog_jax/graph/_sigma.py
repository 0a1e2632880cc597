"""``sigma="auto"``: the 2D noise level from the nearest epipolar distances, with a fallback
when the data hold too little evidence (ALGORITHM.md §0.1).

One sample per node ``u`` and other view ``n``: ``x`` = the distance of ``u``'s epipolar line
to the nearest point of view ``n``. That nearest point is the true match (half-normal
distance ``T``, scale ``c = √2 σ``: both points' noise) unless an unrelated point lies
nearer; the nearest of ``k`` unrelated points is exponential with rate ``κ k`` (points
scattered over the image). Three kinds of sample, modelled jointly (a censored mixture):

- ``match``: a true match exists and is nearest: ``x = T``, every unrelated point farther;
- ``hidden``: a true match exists but an unrelated point is nearer: ``T > x``;
- ``none``: no true match in view ``n`` (clutter, a point that ``n`` does not see):
  ``x`` is the nearest unrelated distance;

plus a uniform on ``[0, W]`` for anything else (far-off detections). EM with closed-form
steps (the censored half-normal and exponential moments) runs a fixed number of iterations
from several low-quantile starts: each takes :data:`SELECT_AFTER` of them, then the most
likely goes on alone.

The estimate is not trusted (``fallback``) when the expected number of pairs with a true
match is below :data:`MIN_MATCHES` (then ``σ = FALLBACK_SIGMA_PX``), or when ``σ̂`` exceeds
:data:`MAX_SIGMA_PER_FOCAL` of the focal length (then ``σ`` is that bound: a scene of few
points with large noise, such as one joint type of real pose detections, must not get the
small fallback).
"""

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import erfinv

from .._types import Array, Bool, Float, Int

EM_ITERS = 40
START_QUANTILES = (0.1, 0.25, 0.5)  # the half-normal scale starts from these sample quantiles
SELECT_AFTER = 10  # EM steps of every start; the most likely then goes on alone to EM_ITERS
MIN_MATCHES = 2.5  # expected true-match pairs needed to use σ̂ (three pairs that fit well)
MAX_SIGMA_PER_FOCAL = 0.01  # a plausible σ is at most 1 % of the focal length
UNIFORM_PER_FOCAL = 0.1  # the uniform spans at least 10 % of the focal length
SPREAD_PER_FOCAL = (
    0.05  # 1/κ (a point's mean nearest distance to a line when alone) is at least this
)
FALLBACK_SIGMA_PX = 1.0
TIE_RELATIVE = 1e-5  # log-likelihoods this close (relative) count as equal
MIN_SCALE_PX = 1e-3  # the half-normal scale's floor (noise-free data: every distance ≈ 0)


def nearest_samples(
    d: Float[Array, "M P M P"], mask: Bool[Array, "M P"]
) -> tuple[Float[Array, "M P M"], Float[Array, "M P M"], Float[Array, "M P M"]]:
    """``x[m, i, n] = min_j d[m, i, n, j]`` (pixels, 0 where unused), its weight (½ where
    finite, else 0: a pair of nodes gives two samples that count once) and the number of
    valid points of view ``n``."""
    x = jnp.min(d, axis=-1)
    ok = jnp.isfinite(x) & mask[:, :, None]
    count = jnp.broadcast_to(jnp.sum(mask, axis=1).astype(d.dtype)[None, None, :], x.shape)
    return jnp.where(ok, x, 0.0), jnp.where(ok, 0.5, 0.0).astype(d.dtype), count


def table_sum(values: Float[Array, " S"], width: int | None = None) -> Float[Array, ""]:
    """``Σ values`` of a table of ``S`` samples; with ``width`` (``>= S``), summed as the
    table padded with zeros to ``width`` entries (an entry of weight 0 adds an exact zero to
    every sum of a fit). XLA's CPU compiler orders a sum by its length (windows of 32, their
    sums summed the same way), so that a fit of a narrower table whose sums are padded to a
    power of two is bitwise the fit of the table of that width, at the per-sample cost (the
    EM's) of the narrower one."""
    return table_sums(values[None], width)[0]


def table_sums(values: Float[Array, "K S"], width: int | None = None) -> Float[Array, " K"]:
    """The ``K`` sums of :func:`table_sum` of the rows of ``values``, in one reduction (one
    kernel where ``K`` separate sums are ``K``), each row's bitwise its :func:`table_sum`."""
    size = values.shape[-1]
    if width is not None and width != size:
        values = jnp.pad(values, ((0, 0), (0, width - size)))
    return jnp.sum(values, axis=-1)


SERIES_FROM = {4: 10.0, 8: 30.0}
"""log_half_normal_tail's switch to the asymptotic series, by bytes per float: where ``erfc``
nears the smallest numbers of float32 (as ``log_ndtr``'s switch) and of float64."""


def log_half_normal_tail(a: Float[Array, " S"]) -> Float[Array, " S"]:
    """``log Q(a) = log P(Z > a)`` of a standard normal for ``a ≥ 0``: ``log_ndtr(-a)``
    within round-off at a third of its cost (the EM's largest): ``½ erfc(a / √2)`` up to
    :data:`SERIES_FROM`, the first terms of the asymptotic series beyond; ``log_ndtr``
    evaluates both ``erf`` and ``erfc`` and its series on every entry."""
    switch = SERIES_FROM[jnp.dtype(a.dtype).itemsize]
    near = a < switch
    tail = 0.5 * jax.lax.erfc(jnp.minimum(a, switch) * np.sqrt(0.5))
    far = jnp.maximum(a, switch)
    inv2 = 1.0 / (far * far)
    # Far out, log Q(a) = -a²/2 - log(2π)/2 + log((1 + series) / a): one logarithm for both.
    ratio = (1.0 + inv2 * (-1.0 + inv2 * (3.0 - 15.0 * inv2))) / far
    exponent = jnp.where(near, 0.0, -0.5 * far * far - 0.5 * np.log(2.0 * np.pi))
    return jnp.log(jnp.where(near, tail, ratio)) + exponent


def half_normal_beyond_moment(x: Float[Array, " S"], c: Float[Array, ""]) -> Float[Array, " S"]:
    """``E[T² | T > x]`` (px²) of a half-normal ``T`` of scale ``c``, per sample:
    ``c² (1 + a φ(a) / Q(a))`` with ``a = x / c``."""
    a = x / c
    # a < φ(a) / Q(a) < a + 1/a bounds the round-off of the ratio far in the tail.
    mills = jnp.exp(-0.5 * a * a - 0.5 * jnp.log(2.0 * jnp.pi) - log_half_normal_tail(a))
    mills = jnp.clip(mills, a, a + 1.0 / jnp.maximum(a, MIN_SCALE_PX))
    return c * c * (1.0 + a * mills)


def mixture_log_parts(x, count, log_t, log_t_beyond, inv_kappa, pi, width):
    """Log joint density ``(4, S)`` of every sample ``x`` under match / hidden / none /
    uniform, given the true-pair distance's log density at ``x`` (``log_t``) and the log
    probability that it lies beyond where a hidden match must (``log_t_beyond``); shared by
    every shape of the true-pair distance."""
    kappa = 1.0 / inv_kappa
    log_kappa = -jnp.log(inv_kappa)
    lam_true = (count - 1.0) * kappa  # rate of the nearest unrelated point beside a true match
    lam_none = count * kappa
    has_other = count > 1.0
    # log(count − 1) and log(count) do not change between EM steps (XLA computes them once).
    log_lam_true = jnp.log(jnp.where(has_other, count - 1.0, 1.0)) + log_kappa
    match = log_t - lam_true * x
    hidden = jnp.where(has_other, log_lam_true - lam_true * x + log_t_beyond, -jnp.inf)
    none = jnp.log(count) + log_kappa - lam_none * x
    uniform = jnp.broadcast_to(-jnp.log(width), x.shape)
    return jnp.stack(
        [
            match + jnp.log(pi[0]),
            hidden + jnp.log(pi[0]),
            none + jnp.log(pi[1]),
            uniform + jnp.log(pi[2]),
        ]
    )


def _log_parts(x, count, c, inv_kappa, pi, width):
    """Log joint density ``(4, S)`` of every sample, the true-pair distance half-normal."""
    a = x / c
    log_hn = 0.5 * jnp.log(2.0 / jnp.pi) - jnp.log(c) - 0.5 * a * a
    log_t_beyond = jnp.log(2.0) + log_half_normal_tail(a)  # log P(T > x)
    return mixture_log_parts(x, count, log_hn, log_t_beyond, inv_kappa, pi, width)


def run_em(
    log_parts,
    true_moments,
    x,
    w,
    count,
    c0,
    inv_kappa0,
    width,
    spread_min,
    pi0=None,
    iters=None,
    sum_width=None,
):
    """``iters`` (default :data:`EM_ITERS`) steps of the censored mixture from the scale
    ``c0``, the unrelated points' spread ``inv_kappa0`` and the shares ``pi0`` (default 0.6,
    0.3, 0.1); returns ``(c, inv_kappa, pi)``. ``log_parts(c, inv_kappa,
    pi)``: the ``(4, S)`` log joint densities; ``true_moments(c, match, hidden)``: ``(S,)``
    each sample's share of ``Σ E[T²]`` over the true pairs (its responsibilities
    ``match``, ``hidden`` times the squared distance they imply), so that
    ``c² = Σ / n_true``. ``sum_width``: the width the table's sums are padded to
    (:func:`table_sum`)."""
    total = jnp.maximum(table_sum(w, sum_width), MIN_SCALE_PX)
    max_count = jnp.maximum(jnp.max(jnp.where(w > 0, count, 1.0)), 1.0)

    def step(_, state):
        c, inv_kappa, pi = state
        resp = jax.nn.softmax(log_parts(c, inv_kappa, pi), axis=0) * w[None]
        match, hidden, none, uniform = resp
        # (count − 1)·U is exponential with mean 1/κ; beside a match it is only known to exceed x.
        others = jnp.where(count > 1.0, count - 1.0, 0.0)
        censored = jnp.where(count > 1.0, match, 0.0)
        # The step's six sums in one reduction: a step is a few dozen small kernels, and a
        # kernel costs about as much to launch as to sum a table.
        n_true, moments, seen, exposed, n_none, n_uniform = table_sums(
            jnp.stack(
                [
                    match + hidden,
                    true_moments(c, match, hidden),
                    hidden * others * x + none * count * x + censored * (others * x + inv_kappa),
                    hidden + none + censored,
                    none,
                    uniform,
                ]
            ),
            sum_width,
        )
        c_new = jnp.sqrt(moments / jnp.maximum(n_true, MIN_SCALE_PX))
        inv_kappa = seen / jnp.maximum(exposed, MIN_SCALE_PX)
        c = jnp.clip(c_new, MIN_SCALE_PX, width)
        inv_kappa = jnp.clip(inv_kappa, spread_min, width * max_count)
        pi = jnp.clip(jnp.stack([n_true, n_none, n_uniform]) / total, 1e-4, 1.0)
        return c, inv_kappa, pi / jnp.sum(pi)

    if pi0 is None:
        pi0 = jnp.asarray([0.6, 0.3, 0.1], x.dtype)
    iters = EM_ITERS if iters is None else iters
    return jax.lax.fori_loop(0, iters, step, (c0, inv_kappa0, pi0))


def most_likely(log_lik: Float[Array, " Q"]) -> Int[Array, ""]:
    """The index of the largest log-likelihood; fits that reach one optimum differ only by
    round-off, so near-ties (within :data:`TIE_RELATIVE`) go to the first; NaN loses."""
    log_lik = jnp.where(jnp.isfinite(log_lik), log_lik, -jnp.inf)
    top = jnp.max(log_lik)
    return jnp.argmax(log_lik >= top - TIE_RELATIVE * (1.0 + jnp.abs(top)))


def estimate_sigma(
    d: Float[Array, "M P M P"], mask: Bool[Array, "M P"], focal_px: Float[Array, ""]
) -> tuple[Float[Array, ""], Bool[Array, ""]]:
    """Noise estimate ``σ`` (pixels) from the epipolar distance table ``d (M, P, M, P)``,
    ``mask (M, P)`` and the rig's focal length ``focal_px`` (sets the plausible range).

    Returns ``(sigma, fallback)``: ``fallback`` is True when the fit is not trusted: fewer
    than ``MIN_MATCHES`` expected true pairs (then ``sigma = FALLBACK_SIGMA_PX``), or
    ``σ̂ > MAX_SIGMA_PER_FOCAL · focal_px`` (then ``sigma`` is that bound). Always finite.
    """
    return sigma_from_samples(*nearest_samples(d, mask), focal_px)


def sorted_at(values: Float[Array, " S"], ranks: Int[Array, " Q"]) -> Float[Array, " Q"]:
    """``jnp.sort(values)[ranks]`` for ``values ≥ 0`` (``+inf`` and a NaN of positive
    sign allowed, both last; ``-0`` reads as ``+0``), without the sort: the bits of a
    non-negative float order as the float does, so each value is bisected bit by bit,
    ``(Q, S)`` comparisons a step. XLA's CPU sort compares through a call per pair: a σ
    fit's 1,024 samples took 0.12 ms to sort."""
    itype = {4: jnp.int32, 8: jnp.int64}[jnp.dtype(values.dtype).itemsize]
    bits = jax.lax.bitcast_convert_type(jnp.where(values == 0, 0.0, values), itype)
    steps = 8 * jnp.dtype(itype).itemsize - 1
    # The answer lies in (low, high]: fewer than rank + 1 bits at or below low, more at high.
    low = jnp.full(ranks.shape, -1, itype)
    high = jnp.full(ranks.shape, jnp.iinfo(itype).max, itype)

    def halve(_, bounds):
        low, high = bounds
        mid = (low & high) + ((low ^ high) >> 1)  # their mean, rounded down, not overflowing
        above = jnp.sum(bits[None, :] <= mid[:, None], axis=1, dtype=ranks.dtype) > ranks
        return jnp.where(above, low, mid), jnp.where(above, mid, high)

    _, high = jax.lax.fori_loop(0, steps, halve, (low, high))
    return jax.lax.bitcast_convert_type(high, values.dtype)


def em_start(
    x: Float[Array, " S"],
    w: Float[Array, " S"],
    count: Float[Array, " S"],
    focal_px: Float[Array, ""],
    sum_width: int | None = None,
) -> tuple[
    Float[Array, ""], Float[Array, ""], Float[Array, " Q"], Float[Array, ""], Float[Array, ""]
]:
    """What every EM over nearest distances starts from (flat samples ``x, w, count``, px):
    ``(focal_px, width, c0, scaled_mean, spread_min)``: the focal length made usable (1 px
    when not finite or positive), the width of the uniform part, the half-normal scales
    ``c0 (len(START_QUANTILES),)`` that put each start quantile of the distances at its
    half-normal quantile, the mean of ``count · x`` (an unrelated point's spread) and the
    smallest spread allowed. ``sum_width``: as :func:`run_em`'s."""
    n = jnp.sum(w > 0)
    focal_px = jnp.where(jnp.isfinite(focal_px) & (focal_px > 0), focal_px, 1.0)
    width = jnp.maximum(jnp.max(x), UNIFORM_PER_FOCAL * focal_px)

    last = jnp.maximum(n - 1, 0).astype(x.dtype)
    # A half-normal's q-quantile is c · Φ⁻¹((1 + q) / 2) = c · √2 erfinv(q).
    q = jnp.asarray(START_QUANTILES, x.dtype)
    z = jnp.sqrt(2.0) * erfinv(q)
    at_q = sorted_at(jnp.where(w > 0, x, jnp.inf), jnp.floor(q * last).astype(jnp.int32))
    c0 = jnp.clip(jnp.where(jnp.isfinite(at_q), at_q, 0.0) / z, MIN_SCALE_PX, width)
    scaled_mean = table_sum(w * count * x, sum_width) / jnp.maximum(
        table_sum(w, sum_width), MIN_SCALE_PX
    )
    return focal_px, width, c0, scaled_mean, SPREAD_PER_FOCAL * focal_px


def sigma_from_samples(
    x: Float[Array, "*S"],
    w: Float[Array, "*S"],
    count: Float[Array, "*S"],
    focal_px: Float[Array, ""],
    *,
    sum_width: int | None = None,
) -> tuple[Float[Array, ""], Bool[Array, ""]]:
    """:func:`estimate_sigma` from the samples of :func:`nearest_samples` (any shape, e.g.
    those of several scenes pooled; weight 0 marks an unused entry). ``sum_width``: the
    width the samples' sums are padded to (:func:`table_sum`): σ is then that of the
    samples padded with unused entries to ``sum_width``, bit for bit."""
    x, w, count = (a.reshape(-1) for a in (x, w, count))
    dtype = x.dtype
    focal_px, width, c0, scaled_mean, spread_min = em_start(x, w, count, focal_px, sum_width)
    inv_kappa0 = jnp.clip(scaled_mean, spread_min, width * jnp.maximum(jnp.max(count), 1.0))

    def log_parts(c, inv_kappa, pi):
        return _log_parts(x, count, c, inv_kappa, pi, width)

    def true_moments(c, match, hidden):
        return match * x * x + hidden * half_normal_beyond_moment(x, c)

    em_steps = partial(run_em, log_parts, true_moments, x, w, count, sum_width=sum_width)

    def em(c, inv_kappa, pi, iters):
        c, inv_kappa, pi = em_steps(c, inv_kappa, width, spread_min, pi, iters)
        parts = log_parts(c, inv_kappa, pi)
        return c, inv_kappa, pi, table_sum(w * jax.nn.logsumexp(parts, axis=0), sum_width), parts

    # Every start takes SELECT_AFTER steps; by then the starts bound for one optimum agree
    # and the most likely is on its way to the best one; it alone takes the remaining steps
    # (the EM's cost is per start and step).
    heads = jax.vmap(lambda c: em(c, inv_kappa0, None, SELECT_AFTER)[:4])(c0)
    best = most_likely(heads[3])
    c, _, _, _, parts = em(*(a[best] for a in heads[:3]), EM_ITERS - SELECT_AFTER)
    resp = jax.nn.softmax(parts, axis=0)
    n_match = table_sum(w * (resp[0] + resp[1]), sum_width)
    sigma, fallback = trusted_sigma(c / jnp.sqrt(2.0), n_match, focal_px)
    return sigma.astype(dtype), fallback


def trusted_sigma(
    sigma: Float[Array, ""], n_match: Float[Array, ""], focal_px: Float[Array, ""]
) -> tuple[Float[Array, ""], Bool[Array, ""]]:
    """``(σ, fallback)`` from a fit's ``σ̂`` (pixels) and its expected number of true pairs:
    ``σ̂`` itself where the fit has evidence; :data:`FALLBACK_SIGMA_PX` where it has fewer
    than :data:`MIN_MATCHES` pairs or ``σ̂`` is not finite; the largest plausible σ,
    :data:`MAX_SIGMA_PER_FOCAL` of the focal length ``focal_px``, where ``σ̂`` is above it
    (the data say the noise is large: the fallback, the small σ of a clean rig, would be the
    worst guess there). ``fallback``: either of the last two."""
    most = MAX_SIGMA_PER_FOCAL * focal_px
    thin = ~((n_match >= MIN_MATCHES) & jnp.isfinite(sigma))
    return jnp.where(thin, FALLBACK_SIGMA_PX, jnp.minimum(sigma, most)), thin | (sigma > most)


def focal_scale(
    K: Float[Array, "M 3 3"] | Float[np.ndarray, "M 3 3"],
) -> Float[Array, ""] | Float[np.ndarray, ""]:
    """The rig's focal length ``()`` (pixels) from ``K (M, 3, 3)``: the median over views of
    ``(|f_x| + |f_y|) / 2``. A NumPy ``K`` gives a NumPy scalar, bitwise the same: outside
    ``jit`` the host computes it (as eager JAX operations, each a program compiled in every
    process)."""
    xp = np if isinstance(K, np.ndarray) else jnp
    return xp.asarray(
        xp.median(xp.asarray(0.5, K.dtype) * (xp.abs(K[..., 0, 0]) + xp.abs(K[..., 1, 1])))
    )
