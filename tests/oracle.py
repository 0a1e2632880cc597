"""A plain NumPy (float64) oracle of the whole association pipeline of docs/ALGORITHM.md.

Written from docs/ALGORITHM.md only, independently of the JAX code, for clarity rather
than speed (Python loops over nodes, edges and groups). The tests compare it with the
jitted pipeline (tests/test_pipeline_vs_oracle.py) and test it on its own
(tests/test_oracle_self.py).

Notation as in ALGORITHM.md: ``M`` views, ``P`` slots, node ``u = m * P + i``.
Section numbers (§) refer to docs/ALGORITHM.md.

Besides the oracle this module holds a small numpy scene generator (:func:`make_rig`,
:func:`make_scene`) shared by the tests.
"""

from __future__ import annotations

import math
from statistics import NormalDist

import numpy as np
from scipy import stats as scipy_stats

__all__ = [
    "fundamental_matrices",
    "epipolar_distance_table",
    "tau_px",
    "estimate_sigma",
    "estimate_sigma_robust",
    "directed_edges",
    "adjacency",
    "overlap_theta",
    "components",
    "conflicting_labels",
    "prune_weak_edges",
    "edge_epipolar",
    "split_view_unique",
    "project",
    "triangulate_dlt",
    "triangulate_dlt_svd",
    "iqr_scores",
    "iqr_outliers",
    "second_association",
    "group_bpe",
    "bpe_jump_keep",
    "support_keep",
    "support_test",
    "detach_ambiguous",
    "validity_gate",
    "dissolve_ambiguous",
    "off_plane_deg",
    "oracle_associate",
    "look_at",
    "make_rig",
    "make_scene",
]


# ----------------------------------------------------------------------------- geometry


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def fundamental_matrices(K, R, t):
    """``F[m, n]`` (M, M, 3, 3) mapping a pixel of view m to its epipolar line in view n (§1).

    ``F[m, n] = K_n^{-T} [t_rel]_x R_rel K_m^{-1}``, ``R_rel = R_n R_mᵀ``,
    ``t_rel = t_n − R_rel t_m``, scaled to unit Frobenius norm. ``F[m, m] = 0``.
    """
    K, R, t = (np.asarray(a, np.float64) for a in (K, R, t))
    M = K.shape[0]
    F = np.zeros((M, M, 3, 3))
    for m in range(M):
        for n in range(M):
            if m == n:
                continue
            R_rel = R[n] @ R[m].T
            t_rel = t[n] - R_rel @ t[m]
            f = np.linalg.inv(K[n]).T @ _skew(t_rel) @ R_rel @ np.linalg.inv(K[m])
            norm = np.linalg.norm(f)
            F[m, n] = f / norm if norm > 0 else f
    return F


def epipolar_distance_table(K, R, t, xy, mask):
    """``d[m, i, n, j]`` (M, P, M, P): distance in image n from (n, j) to the epipolar line of
    (m, i) (§1); ``+inf`` for ``m == n``, invalid nodes or a degenerate line."""
    xy = np.asarray(xy, np.float64)
    mask = np.asarray(mask, bool)
    M, P = mask.shape
    F = fundamental_matrices(K, R, t)
    d = np.full((M, P, M, P), np.inf)
    for m in range(M):
        for i in range(P):
            if not mask[m, i]:
                continue
            x = np.array([xy[m, i, 0], xy[m, i, 1], 1.0])
            for n in range(M):
                if n == m:
                    continue
                line = F[m, n] @ x
                nrm2 = line[0] ** 2 + line[1] ** 2
                if nrm2 == 0:
                    continue
                for j in range(P):
                    if not mask[n, j]:
                        continue
                    y = np.array([xy[n, j, 0], xy[n, j, 1], 1.0])
                    d[m, i, n, j] = abs(line @ y) / math.sqrt(nrm2)
    return d


def project(K, R, t, X):
    """Pixels of one world point ``X`` (3,) in every view, (M, 2); divides by the third
    homogeneous coordinate whatever its sign."""
    K, R, t = (np.asarray(a, np.float64) for a in (K, R, t))
    out = np.zeros((K.shape[0], 2))
    for m in range(K.shape[0]):
        h = K[m] @ (R[m] @ X + t[m])
        out[m] = h[:2] / h[2]
    return out


def _normalised(K, xy_views):
    """``x̂ = K⁻¹ (x, y, 1)`` dehomogenised, (M, 2)."""
    out = np.zeros((K.shape[0], 2))
    for m in range(K.shape[0]):
        h = np.linalg.inv(K[m]) @ np.array([xy_views[m, 0], xy_views[m, 1], 1.0])
        out[m] = h[:2] / h[2]
    return out


def triangulate_dlt(K, R, t, xy_views, mask_views, center=None):
    """Multi-view DLT of §9: rows ``x̂ P3 − P1``, ``ŷ P3 − P2`` with ``P = [R | t + R c̄]``,
    inhomogeneous least squares through the 3×3 normal equations, ``X = X' + c̄``.

    ``xy_views`` (M, 2) one observation per view, ``mask_views`` (M,) which views to use.
    ``center`` is the origin shift c̄; by default the mean centre of the views used (any
    choice gives the same point up to rounding: the algebraic residuals are translation
    equivariant).
    """
    K, R, t = (np.asarray(a, np.float64) for a in (K, R, t))
    xy_views = np.asarray(xy_views, np.float64)
    used = np.flatnonzero(np.asarray(mask_views, bool))
    centres = np.stack([-R[m].T @ t[m] for m in range(K.shape[0])])
    c_bar = centres[used].mean(axis=0) if center is None else np.asarray(center, np.float64)
    xn = _normalised(K, xy_views)
    N = np.zeros((3, 3))
    rhs = np.zeros(3)
    for m in used:
        Pm = np.concatenate([R[m], (t[m] + R[m] @ c_bar)[:, None]], axis=1)
        rows = np.stack([xn[m, 0] * Pm[2] - Pm[0], xn[m, 1] * Pm[2] - Pm[1]])
        A, b = rows[:, :3], rows[:, 3]
        N += A.T @ A
        rhs -= A.T @ b
    return np.linalg.solve(N, rhs) + c_bar


def triangulate_dlt_svd(K, R, t, xy_views, mask_views):
    """Homogeneous DLT in pixel coordinates (rows ``x P3 − P1``, ``y P3 − P2`` with
    ``P = K [R | t]``), solved by SVD. For cross-checking :func:`triangulate_dlt`: both
    are exact on noise-free data, they differ (slightly) with noise."""
    K, R, t = (np.asarray(a, np.float64) for a in (K, R, t))
    rows = []
    for m in np.flatnonzero(np.asarray(mask_views, bool)):
        Pm = K[m] @ np.concatenate([R[m], t[m][:, None]], axis=1)
        x, y = xy_views[m]
        rows.append(x * Pm[2] - Pm[0])
        rows.append(y * Pm[2] - Pm[1])
    _, _, vt = np.linalg.svd(np.stack(rows))
    Xh = vt[-1]
    return Xh[:3] / Xh[3]


# ----------------------------------------------------------------------------- §0 noise


def tau_px(sigma, alpha_tau, tau_min_px):
    """``tau = max(alpha_tau · √2 · σ, tau_min)`` (§0)."""
    return max(alpha_tau * math.sqrt(2.0) * sigma, tau_min_px)


def sigma_samples(d, mask):
    """§0.1 samples: for valid u = (m, i) and views n ≠ m with a valid point, the finite
    distance ``min_j d(u; n, j)``, the number of valid points of view n and the second
    smallest distance (the smallest where there is no finite second). Returns three 1-D
    arrays (distances, counts, second distances)."""
    mask = np.asarray(mask, bool)
    M, P = mask.shape
    x, count, second = [], [], []
    for m in range(M):
        for i in range(P):
            if not mask[m, i]:
                continue
            for n in range(M):
                if n == m or not mask[n].any():
                    continue
                row = np.sort(d[m, i, n][mask[n]])
                if np.isfinite(row[0]):
                    x.append(float(row[0]))
                    count.append(float(mask[n].sum()))
                    second.append(
                        float(row[1]) if row.size > 1 and np.isfinite(row[1]) else float(row[0])
                    )
    return np.asarray(x, np.float64), np.asarray(count, np.float64), np.asarray(second, np.float64)


def focal_scale(K):
    """Median over views of ``(|f_x| + |f_y|) / 2`` (pixels)."""
    K = np.asarray(K, np.float64)
    return float(np.median(0.5 * (np.abs(K[:, 0, 0]) + np.abs(K[:, 1, 1]))))


def _log_q(a):
    """``log Q(a) = log P(Z > a)`` for a ≥ 0, stable in the tail: float64's ``erfc`` up to
    37 (before it underflows), the asymptotic series beyond (its next term ≤ 1e-12)."""
    return np.array(
        [
            math.log(0.5 * math.erfc(v / math.sqrt(2.0)))
            if v < 37
            else -0.5 * v * v
            - math.log(v * math.sqrt(2.0 * math.pi))
            + math.log1p(-1.0 / v**2 + 3.0 / v**4 - 15.0 / v**6)
            for v in np.atleast_1d(np.asarray(a, np.float64))
        ]
    )


_NU_GRID = (math.inf, 8.0, 4.0, 2.0)  # the match distance's degrees of freedom (inf: half-normal)


def _log_match(x, c, nu):
    """Half-normal / half-t of scale c: log density at x, log P(T > x)."""
    a = x / c
    if math.isinf(nu):
        return 0.5 * math.log(2.0 / math.pi) - math.log(c) - 0.5 * a * a, math.log(2.0) + _log_q(a)
    log_pdf = math.log(2.0) + scipy_stats.t.logpdf(a, nu) - math.log(c)
    return log_pdf, math.log(2.0) + scipy_stats.t.logsf(a, nu)


def _moments(x, c, nu):
    """E[u T²] of a match at x and E[u T² | T > x] (u: the t's latent precision; 1 for the
    half-normal)."""
    a = x / c
    if math.isinf(nu):
        mills = np.exp(-0.5 * a * a - 0.5 * math.log(2.0 * math.pi) - _log_q(a))
        mills = np.clip(mills, a, a + 1.0 / np.maximum(a, 1e-3))
        return x * x, c * c * (1.0 + a * mills)
    # E[u Z² 1{Z > a}] = (ν + 1) S_ν(a) − ν S_{ν+2}(a √((ν + 2) / ν)) for Z ~ t_ν.
    s_nu = scipy_stats.t.sf(a, nu)
    s_up = scipy_stats.t.sf(a * math.sqrt((nu + 2.0) / nu), nu + 2.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(s_nu > 0, (nu + 1.0) - nu * s_up / s_nu, nu + 1.0)
    return (nu + 1.0) / (nu + a * a) * x * x, c * c * np.clip(ratio, 1.0, nu + 1.0)


def _sigma_log_parts(x, x2, count, c, inv_kappa, pi, width, nu):
    """Log joint density (4, S): match, hidden, none, uniform (§0.1)."""
    lam_true = (count - 1.0) / inv_kappa
    lam_none = count / inv_kappa
    log_t, _ = _log_match(x, c, nu)
    _, log_beyond = _log_match(
        x2, c, nu
    )  # a hidden true match lies at or beyond the second nearest
    other = count > 1.0
    with np.errstate(divide="ignore"):
        hidden = np.where(
            other, np.log(np.where(other, lam_true, 1.0)) - lam_true * x + log_beyond, -np.inf
        )
        none = np.log(lam_none) - lam_none * x
    return np.stack(
        [
            log_t - lam_true * x + math.log(pi[0]),
            hidden + math.log(pi[0]),
            none + math.log(pi[1]),
            np.full(x.shape, -math.log(width) + math.log(pi[2])),
        ]
    )


def _sigma_log_parts_normal(x, count, c, inv_kappa, pi, width):
    """Log joint density (4, S): match, hidden, none, uniform (§0.1)."""
    a = x / c
    lam_true = (count - 1.0) / inv_kappa
    lam_none = count / inv_kappa
    log_hn = 0.5 * math.log(2.0 / math.pi) - math.log(c) - 0.5 * a * a
    other = count > 1.0
    with np.errstate(divide="ignore"):
        hidden = np.where(
            other,
            np.log(np.where(other, lam_true, 1.0)) - lam_true * x + math.log(2.0) + _log_q(a),
            -np.inf,
        )
        none = np.log(lam_none) - lam_none * x
    return np.stack(
        [
            log_hn - lam_true * x + math.log(pi[0]),
            hidden + math.log(pi[0]),
            none + math.log(pi[1]),
            np.full(x.shape, -math.log(width) + math.log(pi[2])),
        ]
    )


def _softmax0(parts):
    top = parts.max(axis=0)
    e = np.exp(parts - top)
    return e / e.sum(axis=0), top + np.log(e.sum(axis=0))


def estimate_sigma(d, mask, focal_px, iters=40, select_after=10):
    """§0.1: EM on the censored mixture (a true match nearest / a true match behind a nearer
    unrelated point / no true match / uniform) of the nearest distances, each with weight ½,
    from three starts, each ``select_after`` steps, the most likely of them then alone up to
    ``iters``; σ = c / √2, or the 1 px fallback, or capped at 1 % of the focal length.
    Returns ``(sigma, fallback)``.
    The recipe of ALGORITHM.md §0.1."""
    x, count, _ = sigma_samples(d, mask)
    w = np.full(x.size, 0.5)
    total = max(w.sum(), 1e-3)
    focal = focal_px if np.isfinite(focal_px) and focal_px > 0 else 1.0
    width = max(float(x.max()) if x.size else 0.0, 0.1 * focal)
    spread_min = 0.05 * focal
    top_count = max(float(count.max()) if x.size else 1.0, 1.0)
    xs = np.sort(x)

    def em(c, inv_kappa, pi, steps):
        for _ in range(steps):
            r, _ = _softmax0(_sigma_log_parts_normal(x, count, c, inv_kappa, pi, width))
            match, hidden, none, uniform = r * w
            a = x / c
            mills = np.exp(-0.5 * a * a - 0.5 * math.log(2.0 * math.pi) - _log_q(a))
            mills = np.clip(mills, a, a + 1.0 / np.maximum(a, 1e-3))
            n_true = float(np.sum(match + hidden))
            c_new = math.sqrt(
                float(np.sum(match * x * x + hidden * c * c * (1.0 + a * mills)))
                / max(n_true, 1e-3)
            )
            others = np.where(count > 1.0, count - 1.0, 0.0)
            censored = np.where(count > 1.0, match, 0.0)
            seen = float(
                np.sum(hidden * others * x + none * count * x + censored * (others * x + inv_kappa))
            )
            inv_kappa = seen / max(float(np.sum(hidden + none + censored)), 1e-3)
            c = min(max(c_new, 1e-3), width)
            inv_kappa = min(max(inv_kappa, spread_min), width * top_count)
            pi = np.clip(np.array([n_true, np.sum(none), np.sum(uniform)]) / total, 1e-4, 1.0)
            pi = pi / pi.sum()
        r, log_total = _softmax0(_sigma_log_parts_normal(x, count, c, inv_kappa, pi, width))
        return float(np.sum(w * log_total)), (c, inv_kappa, pi), float(np.sum(w * (r[0] + r[1])))

    fits = []
    for q in (0.1, 0.25, 0.5):
        z = NormalDist().inv_cdf(0.5 * (1.0 + q))  # half-normal quantile / scale
        at_q = float(xs[int(math.floor(q * (x.size - 1)))]) if x.size else 0.0
        c = min(max(at_q / z, 1e-3), width)
        inv_kappa = min(max(float(np.sum(w * count * x)) / total, spread_min), width * top_count)
        fits.append(em(c, inv_kappa, np.array([0.6, 0.3, 0.1]), select_after))
    top = max(f[0] for f in fits)
    best = next(
        k for k, f in enumerate(fits) if f[0] >= top - 1e-5 * (1.0 + abs(top))
    )  # near-ties: the first
    _, (c, _, _), n_match = em(*fits[best][1], iters - select_after)
    return _trusted_sigma(c / math.sqrt(2.0), n_match, focal)


def _trusted_sigma(sigma, n_match, focal):
    """``(σ, fallback)``: 1 px with fewer than 2.5 expected true pairs (or σ̂ not finite),
    σ̂ capped at 1 % of the focal length, fallback for either."""
    thin = not (n_match >= 2.5 and math.isfinite(sigma))
    if thin:
        return 1.0, True
    return min(sigma, 0.01 * focal), sigma > 0.01 * focal


def estimate_sigma_robust(
    d, mask, focal_px, iters=40, coverage=0.9544997361036416, with_gate=False
):
    """§0.1, sigma_mode="robust": EM on the censored mixture (a true match nearest / a true
    match beyond the second-nearest point / no true match / uniform) of the nearest
    distances, each with weight ½, the match distance half-normal or half-t (ν = 8, 4, 2), from three starts each; σ = the
    Gaussian scale of the median of the true-pair distance (under the most likely fit) / √2,
    or the 1 px fallback. Returns ``(sigma, fallback)``, or with ``with_gate``
    ``(sigma, gate, fallback)``: gate = the ``coverage``-quantile (NaN on a fallback). The recipe of ALGORITHM.md §0.1."""
    x, count, x2 = sigma_samples(d, mask)
    w = np.full(x.size, 0.5)
    total = max(w.sum(), 1e-3)
    focal = focal_px if np.isfinite(focal_px) and focal_px > 0 else 1.0
    width = max(float(x.max()) if x.size else 0.0, 0.1 * focal)
    spread_min = 0.05 * focal
    top_count = max(float(count.max()) if x.size else 1.0, 1.0)
    xs = np.sort(x)
    fits = []
    for nu in _NU_GRID:
        for q in (0.1, 0.25, 0.5):
            z = NormalDist().inv_cdf(0.5 * (1.0 + q))  # half-normal quantile / scale
            at_q = float(xs[int(math.floor(q * (x.size - 1)))]) if x.size else 0.0
            c = min(max(at_q / z, 1e-3), width)
            other = count > 1.0
            start = (
                float(np.sum(w[other] * (count[other] - 1.0) * x2[other]))
                / max(float(np.sum(w[other])), 1e-3)
                if other.any()
                else float(np.sum(w * count * x)) / total
            )
            inv_kappa = min(max(start, spread_min), width * top_count)
            pi = np.array([0.6, 0.3, 0.1])
            for _ in range(iters):
                r, _ = _softmax0(_sigma_log_parts(x, x2, count, c, inv_kappa, pi, width, nu))
                match, hidden, none, uniform = r * w
                t2_match, _ = _moments(x, c, nu)
                _, t2_beyond = _moments(x2, c, nu)
                n_true = float(np.sum(match + hidden))
                c_new = math.sqrt(
                    float(np.sum(match * t2_match + hidden * t2_beyond)) / max(n_true, 1e-3)
                )
                others = np.where(count > 1.0, count - 1.0, 0.0)
                censored = np.where(count > 1.0, match, 0.0)
                seen = float(
                    np.sum(
                        hidden * others * x + none * count * x + censored * (others * x + inv_kappa)
                    )
                )
                inv_kappa = seen / max(float(np.sum(hidden + none + censored)), 1e-3)
                c = min(max(c_new, 1e-3), width)
                inv_kappa = min(max(inv_kappa, spread_min), width * top_count)
                pi = np.clip(np.array([n_true, np.sum(none), np.sum(uniform)]) / total, 1e-4, 1.0)
                pi = pi / pi.sum()
            r, log_total = _softmax0(_sigma_log_parts(x, x2, count, c, inv_kappa, pi, width, nu))
            fits.append((float(np.sum(w * log_total)), nu, r * w, c))
    top = max(f[0] for f in fits)
    best = next(
        k for k, f in enumerate(fits) if f[0] >= top - 1e-5 * (1.0 + abs(top))
    )  # near-ties: the first
    _, nu, r, c = fits[best]
    n_match = float(np.sum(r[0] + r[1]))
    median = true_distance_quantile(0.5, x, x2, r[0], r[1], c, nu, width)
    sigma, fallback = _trusted_sigma(
        median / (math.sqrt(2.0) * NormalDist().inv_cdf(0.75)), n_match, focal
    )
    gate = (
        math.nan if fallback else true_distance_quantile(coverage, x, x2, r[0], r[1], c, nu, width)
    )
    return (sigma, fallback) if not with_gate else (sigma, gate, fallback)


def true_distance_quantile(q, x, x2, match, hidden, c, nu, width):
    """§0.1: the q-quantile of the true-pair distance: F(t) = Σ (match 1{x ≤ t} + hidden
    P(T ≤ t | T > x2)) / Σ (match + hidden) under the fit (c, ν), solved by bisection on
    [0, width] (120 steps)."""
    n_true = max(float(np.sum(match + hidden)), 1e-3)
    _, log_beyond_x2 = _log_match(x2, c, nu)

    def cdf(t):
        _, log_beyond_t = _log_match(np.full_like(x, t), c, nu)
        passed = -np.expm1(np.minimum(log_beyond_t - log_beyond_x2, 0.0))
        return float(np.sum(match * (x <= t) + hidden * passed)) / n_true

    lo, hi = 0.0, width
    for _ in range(120):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if cdf(mid) < q else (lo, mid)
    return 0.5 * (lo + hi)


# ----------------------------------------------------------------------------- §2 graph


def directed_edges(d, mask, tau):
    """``out[u, n]`` (N, M) int: node index ``n * P + j*`` of the nearest valid point of view
    n to u's epipolar line if closer than ``tau`` (ties: smallest j), else -1 (§2)."""
    mask = np.asarray(mask, bool)
    M, P = mask.shape
    out = np.full((M * P, M), -1, dtype=np.int64)
    for m in range(M):
        for i in range(P):
            if not mask[m, i]:
                continue
            for n in range(M):
                if n == m:
                    continue
                row = d[m, i, n]
                j = int(np.argmin(row))  # first minimum = smallest j
                if row[j] < tau:
                    out[m * P + i, n] = n * P + j
    return out


def adjacency(d, mask, tau, mode="mutual"):
    """Undirected adjacency ``A`` (N, N) bool (§2): ``D ∧ Dᵀ`` (mutual) or ``D ∨ Dᵀ`` (union)."""
    mask = np.asarray(mask, bool)
    M, P = mask.shape
    N = M * P
    out = directed_edges(d, mask, tau)
    D = np.zeros((N, N), bool)
    for u in range(N):
        for n in range(M):
            if out[u, n] >= 0:
                D[u, out[u, n]] = True
    if mode == "mutual":
        A = D & D.T
    elif mode == "union":
        A = D | D.T
    else:
        raise ValueError(mode)
    np.fill_diagonal(A, False)
    return A


def overlap_theta(A):
    """θ of §3 by the literal dense formula: ``C = A + I``, ``O = C Cᵀ``, ``deg = C 1``,
    ``θ[u, v] = O[u, v] / max(deg[u], deg[v])`` on edges, 0 elsewhere. (N, N) float."""
    A = np.asarray(A, bool)
    N = A.shape[0]
    C = A.astype(np.float64) + np.eye(N)
    O = C @ C.T
    deg = C.sum(axis=1)
    theta = O / np.maximum(deg[:, None], deg[None, :])
    return np.where(A, theta, 0.0)


def components(A):
    """Component label of every node: the smallest node index of its component (§4), by
    union-find."""
    A = np.asarray(A, bool)
    N = A.shape[0]
    parent = list(range(N))

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for u in range(N):
        for v in range(u + 1, N):
            if A[u, v]:
                ru, rv = find(u), find(v)
                if ru != rv:
                    parent[max(ru, rv)] = min(ru, rv)  # root = smallest index
    return np.array([find(u) for u in range(N)], dtype=np.int64)


def conflicting_labels(labels, M, P):
    """Labels of the components holding two nodes of one view."""
    bad = set()
    for lab in np.unique(labels):
        members = np.flatnonzero(labels == lab)
        views = members // P
        if len(np.unique(views)) < len(views):
            bad.add(int(lab))
    return bad


def prune_weak_edges(A, theta, delta, scope, M, P):
    """§3: remove weak edges (θ < δ) everywhere (``"all"``), only inside components of A that
    violate view-uniqueness (``"conflicts"``), or nowhere (``"none"``). Returns ``A1``."""
    A1 = np.array(A, bool)
    if scope == "none":
        return A1
    weak = A1 & (theta < delta)
    if scope == "all":
        A1[weak] = False
        return A1
    if scope == "conflicts":
        labels = components(A)
        bad = conflicting_labels(labels, M, P)
        in_bad = np.array([lab in bad for lab in labels])
        A1[weak & in_bad[:, None] & in_bad[None, :]] = False
        return A1
    raise ValueError(scope)


def edge_epipolar(d):
    """``e[u, v] = (d(u; v) + d(v; u)) / 2`` (N, N) (§3)."""
    M, P = d.shape[:2]
    dd = d.reshape(M * P, M * P)
    with np.errstate(invalid="ignore"):
        return (dd + dd.T) / 2.0


def split_view_unique(A1, theta, e, M, P, max_iters):
    """§4: split components until each holds at most one node per view. Returns the graph."""
    A = np.array(A1, bool)
    labels = components(A)
    it = 0
    while it < max_iters:
        bad = conflicting_labels(labels, M, P)
        if not bad:
            break
        for lab in sorted(bad):
            members = set(np.flatnonzero(labels == lab).tolist())
            best = None
            for u in sorted(members):
                for v in np.flatnonzero(A[u]):
                    v = int(v)
                    if v <= u:
                        continue
                    key = (theta[u, v], -e[u, v], u, v)
                    if best is None or key < best:
                        best = key
            _, _, u, v = best
            A[u, v] = A[v, u] = False
        labels = components(A)
        it += 1
    bad = conflicting_labels(labels, M, P)
    if bad:  # last resort, all detachments decided on the graph left by the loop
        detach = []
        for lab in sorted(bad):
            members = np.flatnonzero(labels == lab)
            for view in np.unique(members // P):
                nodes = [int(u) for u in members if u // P == view]
                if len(nodes) < 2:
                    continue
                means = [float(np.mean(e[u][A[u]])) for u in nodes]
                keep = nodes[int(np.argmin(means))]  # first minimum = smallest node index
                detach += [u for u in nodes if u != keep]
        for u in detach:
            A[u, :] = False
            A[:, u] = False
        labels = components(A)
        assert not conflicting_labels(labels, M, P)
    return A, labels


# ----------------------------------------------------------------------------- §6 IQR


def iqr_scores(K, R, t, xy_views, member_mask, score="exclude_own"):
    """Node scores of §6 for one group, (M,) (0 outside the members).

    ``xy_views`` (M, 2) the member observations, ``member_mask`` (M,) the member views.
    """
    K, R, t = (np.asarray(a, np.float64) for a in (K, R, t))
    M = K.shape[0]
    V = [int(v) for v in np.flatnonzero(member_mask)]
    sums = np.zeros(M)
    counts = np.zeros(M)
    for ai, a in enumerate(V):
        for b in V[ai + 1 :]:
            pair = np.zeros(M, bool)
            pair[[a, b]] = True
            X = triangulate_dlt(K, R, t, xy_views, pair)
            proj = project(K, R, t, X)
            for c in V:
                if score == "exclude_own" and c in (a, b):
                    continue
                sums[c] += np.linalg.norm(proj[c] - xy_views[c])
                counts[c] += 1
    scores = np.zeros(M)
    for c in V:
        scores[c] = sums[c] / counts[c]
    return scores


def iqr_outliers(
    scores,
    member_mask,
    alpha,
    quartiles="zero_pad",
    guards=False,
    min_px=10.0,
    force_px=50.0,
    floor_px=0.0,
):
    """Outlier members (M,) bool of one group from its node scores (§6): outside
    ``[max(0, Q1 − α IQR), Q3 + α IQR]`` and above ``floor_px``; then the guards."""
    scores = np.asarray(scores, np.float64)
    member_mask = np.asarray(member_mask, bool)
    s = scores[member_mask]
    out = np.zeros(scores.shape, bool)
    if s.size == 0:
        return out
    if quartiles == "zero_pad":
        values = np.concatenate([s, [0.0]])
    elif quartiles == "positive":
        values = s[s > 0]
    else:
        raise ValueError(quartiles)
    if guards and s.max() < min_px:
        return out
    if values.size > 0:
        q1, q3 = np.percentile(values, [25, 75])
        iqr = q3 - q1
        lb = max(0.0, q1 - alpha * iqr)
        ub = q3 + alpha * iqr
        out = member_mask & ((scores < lb) | (scores > ub)) & (scores > floor_px)
    if guards and not out.any() and s.max() > force_px:
        views = np.flatnonzero(member_mask)
        out[views[int(np.argmax(s))]] = True  # first maximum = lowest view
    return out


# ----------------------------------------------------------------------------- §7 / §8


def second_association(groups, gvalid, d, mask, tau, frac):
    """§7 on a group table ``groups`` (G, M) (slots, -1) with ``gvalid`` (G,); returns the
    new group table (a copy)."""
    mask = np.asarray(mask, bool)
    M, P = mask.shape
    groups = np.array(groups)
    assigned = np.zeros((M, P), bool)
    for g in np.flatnonzero(gvalid):
        for m in range(M):
            if groups[g, m] >= 0:
                assigned[m, groups[g, m]] = True
    picks = []  # (group, view, cost, node)
    for m in range(M):
        for i in range(P):
            if not mask[m, i] or assigned[m, i]:
                continue
            best_cost, best_g = None, None
            for g in np.flatnonzero(gvalid):
                if groups[g, m] >= 0:
                    continue
                ws = []
                for n in range(M):
                    j = groups[g, n]
                    if j < 0:
                        continue
                    dist = d[n, j, m, i]
                    ws.append(dist if dist < tau else 3.0 * dist)
                cost = float(np.mean(ws))
                if best_cost is None or cost < best_cost:
                    best_cost, best_g = cost, int(g)
            if best_g is not None and best_cost < frac * tau:
                picks.append((best_g, m, best_cost, m * P + i))
    winners = {}
    for g, m, cost, u in picks:
        key = (g, m)
        if key not in winners or (cost, u) < winners[key][:2]:
            winners[key] = (cost, u)
    for (g, m), (_, u) in winners.items():
        groups[g, m] = u % P
    return groups


def group_bpe(K, R, t, xy, groups, gvalid):
    """Multi-view DLT point, BPE (mean squared px) and mean reprojection distance of every
    valid group (§8); zeros for invalid groups."""
    xy = np.asarray(xy, np.float64)
    G, M = groups.shape
    pts = np.zeros((G, 3))
    bpe = np.zeros(G)
    err = np.zeros(G)
    for g in np.flatnonzero(gvalid):
        members = groups[g] >= 0
        obs = np.zeros((M, 2))
        for m in np.flatnonzero(members):
            obs[m] = xy[m, groups[g, m]]
        X = triangulate_dlt(K, R, t, obs, members)
        r = np.linalg.norm(project(K, R, t, X) - obs, axis=1)[members]
        pts[g], bpe[g], err[g] = X, np.mean(r**2), np.mean(r)
    return pts, bpe, err


def bpe_jump_keep(bpe, valid, kappa=10.0, floor_px2=4.0, floor_sigma=3.0, sigma=0.0, min_gaps=3):
    """§8 jump rule: which groups (G,) bool stay. Sort valid groups by BPE (ties: group id),
    gaps ``g_i``; the first ``i ≥ min_gaps`` with ``g_i > kappa · median(g_0…g_{i−1})`` and
    ``g_i > floor_px2 + (floor_sigma · sigma)²`` dissolves the groups after it."""
    bpe = np.asarray(bpe, np.float64)
    valid = np.asarray(valid, bool)
    keep = valid.copy()
    ids = np.flatnonzero(valid)
    order = ids[np.argsort(bpe[ids], kind="stable")]  # ids ascending, so ties: group id
    b = bpe[order]
    gaps = np.diff(b)
    floor = floor_px2 + (floor_sigma * sigma) ** 2
    for i in range(min_gaps, len(gaps)):
        if gaps[i] > kappa * np.median(gaps[:i]) and gaps[i] > floor:
            keep[order[i + 1 :]] = False
            break
    return keep


# ----------------------------------------------------------------------------- pipeline


def _table_from_labels(labels, mask, M, P):
    """§5: group table (G, M) and valid (G,) from component labels; groups ordered by label."""
    G = M * P // 2
    groups = np.full((G, M), -1, dtype=np.int64)
    gvalid = np.zeros(G, bool)
    glabel = []
    flat_mask = np.asarray(mask, bool).reshape(-1)
    for lab in np.unique(labels):
        members = [int(u) for u in np.flatnonzero(labels == lab) if flat_mask[u]]
        if len(members) < 2:
            continue
        g = len(glabel)
        glabel.append(int(lab))
        for u in members:
            groups[g, u // P] = u % P
        gvalid[g] = True
    return groups, gvalid


def _group_labels(groups, gvalid, M, P):
    labels = np.full((M, P), -1, dtype=np.int64)
    for g in np.flatnonzero(gvalid):
        for m in range(M):
            if groups[g, m] >= 0:
                labels[m, groups[g, m]] = g
    return labels


def _graph_stage(d, nodes, tau, cfg):
    """§2–§5 on the detections flagged in ``nodes (M, P)``: group table, validity, graphs."""
    M, P = nodes.shape
    d = np.where(nodes[:, :, None, None] & nodes[None, None, :, :], d, np.inf)
    A = adjacency(d, nodes, tau, cfg.adjacency)
    theta = overlap_theta(A)
    A1 = prune_weak_edges(A, theta, cfg.delta, cfg.prune_scope, M, P)
    e = edge_epipolar(d)
    A2, labels = split_view_unique(A1, theta, e, M, P, cfg.max_split_iters)
    groups, gvalid = _table_from_labels(labels, nodes, M, P)
    return groups, gvalid, dict(A=A, theta=theta, A1=A1, A2=A2)


def _iqr_stage(K, R, t, xy, groups, gvalid, cfg):
    """§6, iterated over all groups."""
    M = groups.shape[1]
    groups, gvalid = groups.copy(), gvalid.copy()
    if not cfg.iqr:
        return groups, gvalid
    for _ in range(cfg.max_iqr_iters):
        lost = False
        for g in np.flatnonzero(gvalid):
            members = groups[g] >= 0
            if members.sum() < 3:
                continue
            obs = np.zeros((M, 2))
            for m in np.flatnonzero(members):
                obs[m] = xy[m, groups[g, m]]
            scores = iqr_scores(K, R, t, obs, members, cfg.iqr_score)
            out = iqr_outliers(
                scores,
                members,
                cfg.iqr_alpha,
                cfg.iqr_quartiles,
                cfg.iqr_guards,
                cfg.iqr_min_px,
                cfg.iqr_force_px,
                getattr(cfg, "iqr_floor_px", 0.0),
            )
            if out.any():
                lost = True
                groups[g, out] = -1
                if (groups[g] >= 0).sum() < 2:
                    groups[g] = -1
                    gvalid[g] = False
        if not lost:
            break
    return groups, gvalid


def recover_leftovers(K, R, t, xy, mask, groups, gvalid, pts, tau, frac):
    """§8b: attach leftover detections to the group whose point reprojects closest."""
    M, P = mask.shape
    groups = groups.copy()
    in_group = np.zeros((M, P), bool)
    for g in np.flatnonzero(gvalid):
        for m in np.flatnonzero(groups[g] >= 0):
            in_group[m, groups[g, m]] = True
    choice = {}
    for m in range(M):
        for i in range(P):
            if not mask[m, i] or in_group[m, i]:
                continue
            best, best_err = None, np.inf
            for g in np.flatnonzero(gvalid):
                if groups[g, m] >= 0 or (groups[g] >= 0).sum() < 2:
                    continue
                X_cam = R[m] @ pts[g] + t[m]
                if X_cam[2] <= 0:
                    continue
                err = np.linalg.norm(
                    project(K[m : m + 1], R[m : m + 1], t[m : m + 1], pts[g])[0] - xy[m, i]
                )
                if err < best_err:
                    best, best_err = g, err
            if best is not None and best_err < frac * tau:
                choice[(m, i)] = (best, best_err)
    for (m, i), (g, _err) in sorted(
        choice.items(), key=lambda kv: (kv[1][1], kv[0][0] * P + kv[0][1])
    ):
        if groups[g, m] < 0:
            groups[g, m] = i
    return groups


def _dlt_checked(K, R, t, obs, members):
    """Multi-view DLT point of ``obs (M, 2)`` over ``members (M,)`` and whether its normal
    matrix is well conditioned (``det N > 1e-9 · trace(N)³``, the float64 bound of §9)."""
    xn = _normalised(K, obs)
    N = np.zeros((3, 3))
    for m in np.flatnonzero(members):
        rows = np.stack([xn[m, 0] * R[m][2] - R[m][0], xn[m, 1] * R[m][2] - R[m][1]])
        N += rows.T @ rows
    if members.sum() < 2 or np.linalg.det(N) <= 1e-9 * np.trace(N) ** 3:
        return np.zeros(3), False
    return triangulate_dlt(K, R, t, obs, members), True


def _depth(R, t, m, X):
    return (R[m] @ X + t[m])[2]


def _view_misses(K, R, t, xy, mask, X, m, radius):
    """View ``m`` sees the point ``X`` (in front, inside the bounding box of its detections)
    and holds no detection closer than ``radius`` pixels to its projection."""
    det = xy[m][mask[m]]
    if _depth(R, t, m, X) <= 0 or len(det) == 0:
        return False
    pix = project(K[m : m + 1], R[m : m + 1], t[m : m + 1], X)[0]
    inside = np.all(det.min(0) <= pix) and np.all(pix <= det.max(0))
    return bool(inside and not np.any(np.sum((det - pix) ** 2, axis=1) < radius * radius))


def seed_groups(K, R, t, xy, free, d, tau, gate, min_views, mask=None, support=np.inf, miss=None):
    """§8f: groups seeded from two-view hypotheses on the ``free`` (M, P) detections, as a
    list of (M,) rows in the order they are accepted. A hypothesis whose point a third view
    sees with no detection of ``mask`` within ``support`` pixels is not seeded; with
    ``miss = (q, alpha)`` (the support filter's miss rate and level), only when its ``k``
    such views beside its ``n`` members are implausible: ``P(Bin(n + k, q) ≥ k) < alpha``."""
    mask = free if mask is None else mask
    M, P = free.shape
    hyps = []  # (count, err, index, a, b, distances (M, P) of the other views)
    for m in range(M):
        for i in range(P):
            for n in range(M):
                index = (m * P + i) * M + n
                if n == m or not free[m, i]:
                    continue
                best, best_cost = None, np.inf
                for j in range(P):
                    if free[n, j] and not np.isnan(d[m, i, n, j]) and not np.isnan(d[n, j, m, i]):
                        c = 0.5 * (d[m, i, n, j] + d[n, j, m, i])
                        if c < best_cost:
                            best, best_cost = j, c
                if best is None or not best_cost < tau:
                    continue
                obs = np.zeros((M, 2))
                obs[m], obs[n] = xy[m, i], xy[n, best]
                pair = np.zeros(M, bool)
                pair[[m, n]] = True
                X, ok = _dlt_checked(K, R, t, obs, pair)
                if not ok or _depth(R, t, m, X) <= 0 or _depth(R, t, n, X) <= 0:
                    continue
                pix = project(K, R, t, X)
                dist = np.full((M, P), np.inf)
                total, count = (
                    np.linalg.norm(pix[m] - xy[m, i]) + np.linalg.norm(pix[n] - xy[n, best]),
                    2,
                )
                for v in range(M):
                    if v in (m, n) or _depth(R, t, v, X) <= 0:
                        continue
                    for j in range(P):
                        if free[v, j]:
                            dist[v, j] = np.linalg.norm(pix[v] - xy[v, j])
                    if dist[v].min() < gate:
                        total, count = total + dist[v].min(), count + 1
                k = sum(
                    _view_misses(K, R, t, xy, mask, X, v, support)
                    for v in range(M)
                    if v not in (m, n)
                )
                seen = min(count + k, M)  # a voter's view may be missing too (smaller radius)
                if k and (miss is None or _binomial_tail(seen, k, miss[0]) < miss[1]):
                    continue
                if count >= min_views:
                    hyps.append((-count, total / count, index, (m, i), (n, best), dist))
    hyps.sort(key=lambda h: h[:3])
    used = ~free
    rows = []
    for _, _, _, (m, i), (n, j), dist in hyps:
        if used[m, i] or used[n, j]:
            continue
        row = np.full(M, -1)
        for v in range(M):
            open_ = np.where(used[v], np.inf, dist[v])
            if open_.min() < gate:
                row[v] = int(np.argmin(open_))
        row[m], row[n] = i, j
        if (row >= 0).sum() < min_views:
            continue
        rows.append(row)
        for v in np.flatnonzero(row >= 0):
            used[v, row[v]] = True
    return rows


def _node_errors(K, R, t, xy, mask, groups, gvalid):
    """(G, M, P) distance of every detection to every usable group's point in its view."""
    G, M = groups.shape
    P = mask.shape[1]
    err = np.full((G, M, P), np.inf)
    for g in np.flatnonzero(gvalid):
        members = groups[g] >= 0
        obs = np.zeros((M, 2))
        for m in np.flatnonzero(members):
            obs[m] = xy[m, groups[g, m]]
        X, ok = _dlt_checked(K, R, t, obs, members)
        if not ok:
            continue
        pix = project(K, R, t, X)
        for m in range(M):
            if _depth(R, t, m, X) > 0:
                for i in np.flatnonzero(mask[m]):
                    err[g, m, i] = np.linalg.norm(pix[m] - xy[m, i])
    return err


def reassign_nearest(err, gvalid, gate, rounds):
    """§8g step 1: each detection to its nearest group point within ``gate``, one per
    (group, view), losers retrying the open slots ``rounds`` times."""
    G, M, P = err.shape
    groups = np.full((G, M), -1, dtype=np.int64)
    for _ in range(rounds):
        placed = np.zeros((M, P), bool)
        for g in range(G):
            for m in np.flatnonzero(groups[g] >= 0):
                placed[m, groups[g, m]] = True
        claims = {}
        for m in range(M):
            for i in range(P):
                if placed[m, i]:
                    continue
                best, best_err = None, np.inf
                for g in range(G):
                    if groups[g, m] < 0 and err[g, m, i] < best_err:
                        best, best_err = g, err[g, m, i]
                if best is not None and best_err < gate:
                    claims.setdefault((best, m), []).append((best_err, m * P + i))
        for (g, m), claimants in claims.items():
            groups[g, m] = min(claimants)[1] % P
    gvalid = (groups >= 0).sum(axis=1) >= 2
    groups[~gvalid] = -1
    return groups, gvalid


def merge_split_groups(err, groups, gvalid, gate):
    """§8g step 2: a group moves into the larger group with disjoint views whose point is
    within ``gate`` of all its members (nearest; one per target; a moving group takes none)."""
    G, M = groups.shape
    size = np.where(gvalid, (groups >= 0).sum(axis=1), 0)
    target = np.full(G, -1)
    cost = np.full(G, np.inf)
    for h in range(G):
        if size[h] < 2:
            continue
        for k in range(G):
            if size[k] < 2 or k == h or not (size[k] > size[h] or (size[k] == size[h] and k < h)):
                continue
            if ((groups[k] >= 0) & (groups[h] >= 0)).any():
                continue
            worst = max(err[k, m, groups[h, m]] for m in np.flatnonzero(groups[h] >= 0))
            if worst < gate and worst < cost[h]:
                target[h], cost[h] = k, worst
    moving = target >= 0
    groups, gvalid = groups.copy(), gvalid.copy()
    for k in range(G):
        movers = [(cost[h], h) for h in range(G) if target[h] == k]
        if not movers or moving[k]:
            continue
        h = min(movers)[1]
        groups[k] = np.where(groups[h] >= 0, groups[h], groups[k])
        groups[h] = -1
        gvalid[h] = False
    return groups, gvalid


def reassign_groups(K, R, t, xy, mask, groups, gvalid, tau, cfg, rounds=3):
    """§8g: ``cfg.reassign_iters`` rounds of nearest-point re-assignment and merging."""
    gate = cfg.reassign_frac * tau
    for _ in range(cfg.reassign_iters):
        groups, gvalid = reassign_nearest(
            _node_errors(K, R, t, xy, mask, groups, gvalid), gvalid, gate, rounds
        )
        groups, gvalid = merge_split_groups(
            _node_errors(K, R, t, xy, mask, groups, gvalid), groups, gvalid, gate
        )
    return groups, gvalid


def _free(mask, groups, gvalid):
    free = mask.copy()
    for g in np.flatnonzero(gvalid):
        for m in np.flatnonzero(groups[g] >= 0):
            free[m, groups[g, m]] = False
    return free


def _compact(rows, G, M):
    groups = np.full((G, M), -1, dtype=np.int64)
    gvalid = np.zeros(G, bool)
    for g, row in enumerate(rows[:G]):
        groups[g], gvalid[g] = row, True
    return groups, gvalid


def _seed_stage(K, R, t, xy, mask, d, groups, gvalid, tau, cfg, miss=None):
    G, M = groups.shape
    free = _free(mask, groups, gvalid)
    new = seed_groups(
        K,
        R,
        t,
        xy,
        free,
        d,
        tau,
        cfg.seed_frac * tau,
        cfg.seed_min_views,
        mask,
        cfg.seed_support_frac * tau,
        miss,
    )
    return _compact([groups[g] for g in np.flatnonzero(gvalid)] + new, G, M)


def _binomial_tail(T, k, q):
    """P(Bin(T, q) ≥ k)."""
    return sum(math.comb(T, j) * q**j * (1.0 - q) ** (T - j) for j in range(k, T + 1))


def support_keep(K, R, t, xy, mask, groups, gvalid, pts, tau, cfg):
    """:func:`support_test`'s groups kept."""
    return support_test(K, R, t, xy, mask, groups, gvalid, pts, tau, cfg)[0]


def support_test(K, R, t, xy, mask, groups, gvalid, pts, tau, cfg):
    """Visibility support (§8d, beyond the paper; ``Config.support_filter``).

    A view is *missing* for a valid group when it is not a member view, the group's point is
    in front of it, projects inside the bounding box of the view's detections, and no
    detection lies closer than ``support_frac · τ`` pixels. With ``q`` = the share of
    missing views over the groups with ≥ ``support_ref_views`` members whose point is in
    front of all their cameras (at least ``support_min_rate``), a group of ``n`` members and
    ``k ≥ 1`` missing views is dropped when ``P(Bin(n + k, q) ≥ k) < support_alpha``, and
    any group whose point is behind a member camera is dropped. Returns ``(keep, q)``."""
    K, R, t, xy = (np.asarray(a, np.float64) for a in (K, R, t, xy))
    M = mask.shape[0]
    radius = cfg.support_frac * tau
    gvalid = np.asarray(gvalid, bool)
    n_mem, n_miss, behind = {}, {}, {}
    for g in np.flatnonzero(gvalid):
        X = pts[g]
        pix = project(K, R, t, X)
        n_mem[g], n_miss[g], behind[g] = 0, 0, False
        for m in range(M):
            front = (R[m] @ X + t[m])[2] > 0
            if groups[g, m] >= 0:
                n_mem[g] += 1
                behind[g] |= not front
                continue
            det = xy[m][mask[m]]
            if not front or len(det) == 0:
                continue
            inside = np.all(det.min(0) <= pix[m]) and np.all(pix[m] <= det.max(0))
            near = np.any(np.sum((det - pix[m]) ** 2, axis=1) < radius * radius)
            n_miss[g] += int(inside and not near)
    ref = [g for g in n_mem if not behind[g] and n_mem[g] >= cfg.support_ref_views]
    total = sum(n_mem[g] + n_miss[g] for g in ref)
    q = sum(n_miss[g] for g in ref) / total if total else 0.0
    q = min(max(q, cfg.support_min_rate, 1e-6), 1.0 - 1e-6)
    keep = gvalid.copy()
    for g in n_mem:
        k, T = n_miss[g], n_mem[g] + n_miss[g]
        keep[g] = not behind[g] and (k == 0 or _binomial_tail(T, k, q) >= cfg.support_alpha)
    return keep, q


def detach_ambiguous(K, R, t, xy, mask, groups, gvalid, tau, frac):
    """§8h: every valid group of ≥ 3 members detaches its worst ambiguous member (largest
    own distance; ties: the first view), one whose view holds another detection less than
    ``frac · τ`` farther from the group's point than the member itself. Returns copies."""
    groups = groups.copy()
    M = groups.shape[1]
    for g in np.flatnonzero(gvalid):
        members = groups[g] >= 0
        if members.sum() < 3:
            continue
        obs = np.zeros((M, 2))
        for m in np.flatnonzero(members):
            obs[m] = xy[m, groups[g, m]]
        X, ok = _dlt_checked(K, R, t, obs, members)
        if not ok:
            continue
        pix = project(K, R, t, X)
        worst, worst_err = None, -np.inf
        for m in np.flatnonzero(members):
            if _depth(R, t, m, X) <= 0:
                continue
            dist = np.linalg.norm(xy[m] - pix[m], axis=1)
            own = dist[groups[g, m]]
            others = [dist[j] for j in np.flatnonzero(mask[m]) if j != groups[g, m]]
            if others and min(others) - own < frac * tau and own > worst_err:
                worst, worst_err = m, own
        if worst is not None:
            groups[g, worst] = -1
    return groups


def validity_gate(K, R, t, xy, groups, gvalid, pts, tau, max_err_frac, min_parallax_deg):
    """§12: the rules every valid group obeys. While a group has > 2 members and its worst
    member reprojects farther than ``max_err_frac · τ``, that member is detached and the
    point re-triangulated (at most M − 2 rounds); then a group is dissolved unless its point
    is in front of every member camera, the largest angle between two members' lines of
    sight (folded into [0°, 90°]) is ≥ ``min_parallax_deg`` and every member error is
    within the bound. Returns ``groups, gvalid, pts`` (copies)."""
    K, R, t, xy = (np.asarray(a, np.float64) for a in (K, R, t, xy))
    groups, gvalid, pts = groups.copy(), np.asarray(gvalid, bool).copy(), pts.copy()
    M = groups.shape[1]
    bound = max_err_frac * tau
    centres = np.stack([-R[m].T @ t[m] for m in range(M)])

    def errors(g):
        members = np.flatnonzero(groups[g] >= 0)
        pix = project(K, R, t, pts[g])
        e = np.array([np.linalg.norm(pix[m] - xy[m, groups[g, m]]) for m in members])
        return members, np.where(np.isfinite(e), e, np.inf)

    for g in np.flatnonzero(gvalid):
        for _ in range(M - 2):
            members, e = errors(g)
            if len(members) <= 2 or e.max() <= bound:
                break
            groups[g, members[np.argmax(e)]] = -1
            obs = np.zeros((M, 2))
            for m in np.flatnonzero(groups[g] >= 0):
                obs[m] = xy[m, groups[g, m]]
            pts[g] = triangulate_dlt(K, R, t, obs, groups[g] >= 0)
        members, e = errors(g)
        front = all((R[m] @ pts[g] + t[m])[2] > 0 for m in members)
        rays = pts[g][None, :] - centres[members]
        u = rays / np.linalg.norm(rays, axis=1, keepdims=True)
        parallax = np.degrees(np.arccos(np.clip(np.abs(u @ u.T), 0.0, 1.0)).max())
        if not (len(members) >= 2 and front and parallax >= min_parallax_deg and e.max() <= bound):
            groups[g] = -1
            gvalid[g] = False
    return groups, gvalid, pts


def off_plane_deg(C, X, member, front):
    """Rule 5 (§12): per group, the cameras measured (the members; for a pair, also every
    camera its point is in front of, ``front (G, M)``), the plane through the point ``X (G, 3)``
    and the measured pair of lines of sight farthest from parallel, and the largest angle
    (degrees) of a measured line of sight to that plane; ``inf`` with fewer than three
    measured. ``C (M, 3)``: camera centres."""
    out = np.full(len(X), np.inf)
    for g in range(len(X)):
        members = np.flatnonzero(member[g])
        seen = np.union1d(members, np.flatnonzero(front[g])) if len(members) == 2 else members
        if len(seen) < 3:
            continue
        u = C[seen] - X[g]
        u = u / np.linalg.norm(u, axis=1, keepdims=True)
        a, b = max(
            ((a, b) for a in range(len(seen)) for b in range(len(seen))),
            key=lambda p: np.linalg.norm(np.cross(u[p[0]], u[p[1]])),
        )
        n = np.cross(u[a], u[b])
        out[g] = np.degrees(np.arcsin(min(np.max(np.abs(u @ n)) / np.linalg.norm(n), 1.0)))
    return out


def dissolve_ambiguous(K, R, t, d, groups, gvalid, pts, tau):
    """Rule 5 (§12): a valid group is dissolved when its cameras are within ``asin(τ / f)``
    of one plane with its point (:func:`off_plane_deg`; ``f`` the median focal length) and
    a member view holds another detection within τ of every other member's epipolar line
    (``d (M, P, M, P)``). Returns ``groups, gvalid, dissolved_any`` (copies)."""
    K, R, t = (np.asarray(a, np.float64) for a in (K, R, t))
    groups, gvalid = groups.copy(), np.asarray(gvalid, bool).copy()
    M, P = d.shape[:2]
    C = np.stack([-R[m].T @ t[m] for m in range(M)])
    member = groups >= 0
    front = np.einsum("mij,gj->gmi", R, pts)[..., 2] + t[None, :, 2] > 0
    f = np.median(0.5 * (np.abs(K[:, 0, 0]) + np.abs(K[:, 1, 1])))
    bound = np.degrees(np.arcsin(min(tau / f, 1.0)))
    off = off_plane_deg(C, pts, member & gvalid[:, None], front)
    dissolved = False
    for g in np.flatnonzero(gvalid & (off < bound)):
        members = np.flatnonzero(member[g])
        rival = any(
            p != groups[g, n] and all(d[m, groups[g, m], n, p] <= tau for m in members if m != n)
            for n in members
            for p in range(P)
        )
        if rival:
            groups[g] = -1
            gvalid[g] = False
            dissolved = True
    return groups, gvalid, dissolved


def oracle_associate(K, R, t, xy, mask, config, sigma=1.0, return_stages=False):
    """The whole pipeline of docs/ALGORITHM.md on one scene, in float64 NumPy.

    Args:
        K, R, t: rig, (M, 3, 3), (M, 3, 3), (M, 3).
        xy: (M, P, 2) pixels; mask: (M, P) bool.
        config: a ``cdog_jax.Config`` (structure and numeric fields are read from it).
        sigma: noise std in pixels, or ``"auto"`` (also auto when ``config.sigma_mode ==
            "auto"``).
        return_stages: also return ``"stages"``, a dict of intermediate results
            (``A``, ``theta``, ``A1``, ``A2``, and ``(M, P)`` group-id label maps
            ``labels_split``, ``labels_iqr``, ``labels_second``, ``labels_bpe`` in the
            numbering of §5) for diagnosing mismatches.

    Returns:
        dict with ``labels`` (M, P), ``groups`` (G, M), ``valid`` (G,), ``points3d`` (G, 3),
        ``bpe`` (G,), ``err_px`` (G,), ``n_views`` (G,), ``num_groups``, ``sigma_px``,
        ``tau_px``, laid out like ``cdog_jax.Association`` (valid groups first, §11).
    """
    cfg = config
    if cfg.refine:
        raise NotImplementedError("the oracle does not implement refinement (§10)")
    K, R, t, xy = (np.asarray(a, np.float64) for a in (K, R, t, xy))
    mask = np.asarray(mask, bool)
    M, P = mask.shape
    G = M * P // 2
    stages = {}

    # §1 epipolar distances, §0 noise level and gate
    d = epipolar_distance_table(K, R, t, xy, mask)
    if cfg.sigma_mode == "robust":
        sigma_px, sigma_fallback = estimate_sigma_robust(d, mask, focal_scale(K))
    elif cfg.sigma_mode == "auto" or (isinstance(sigma, str) and sigma == "auto"):
        sigma_px, sigma_fallback = estimate_sigma(d, mask, focal_scale(K))
    else:
        sigma_px, sigma_fallback = float(sigma), False
    tau = tau_px(sigma_px, cfg.alpha_tau, cfg.tau_min_px)

    # §2 adjacency, §3 pruning, §4 view-uniqueness split, §5 group table
    groups, gvalid, graphs = _graph_stage(d, mask, tau, cfg)
    stages.update(graphs, labels_split=_group_labels(groups, gvalid, M, P))

    # §6 IQR
    groups, gvalid = _iqr_stage(K, R, t, xy, groups, gvalid, cfg)
    stages["labels_iqr"] = _group_labels(groups, gvalid, M, P)

    # §7 second association
    if cfg.second_association:
        groups = second_association(groups, gvalid, d, mask, tau, cfg.second_frac)
    stages["labels_second"] = _group_labels(groups, gvalid, M, P)

    # §8 BPE filter
    pts, bpe, err = group_bpe(K, R, t, xy, groups, gvalid)
    if cfg.bpe_filter:
        keep = bpe_jump_keep(
            bpe,
            gvalid,
            cfg.jump_kappa,
            cfg.jump_floor_px2,
            cfg.jump_floor_sigma,
            sigma_px,
            cfg.jump_min_gaps,
        )
        groups[~keep] = -1
        gvalid = keep
    miss = None  # the support filter's miss rate and level, which seeding then uses
    if getattr(cfg, "support_filter", False):  # §8d
        keep, q = support_test(K, R, t, xy, mask, groups, gvalid, pts, tau, cfg)
        groups[~keep] = -1
        gvalid = keep
        miss = (q, cfg.support_alpha)
    stages["labels_bpe"] = _group_labels(groups, gvalid, M, P)

    # §8b recovery by reprojection, §8c regrouping of leftovers
    if cfg.recover:
        groups = recover_leftovers(K, R, t, xy, mask, groups, gvalid, pts, tau, cfg.recover_frac)
    if cfg.regroup:
        left = mask.copy()
        for g in np.flatnonzero(gvalid):
            for m in np.flatnonzero(groups[g] >= 0):
                left[m, groups[g, m]] = False
        new_groups, new_valid, _ = _graph_stage(d, left, tau, cfg)
        new_groups, new_valid = _iqr_stage(K, R, t, xy, new_groups, new_valid, cfg)
        old = [groups[g] for g in np.flatnonzero(gvalid)]
        new = [new_groups[g] for g in np.flatnonzero(new_valid)]
        groups = np.full((G, M), -1, dtype=np.int64)
        gvalid = np.zeros(G, bool)
        for g, row in enumerate(old + new):
            groups[g] = row
            gvalid[g] = True
    # §8f seeding from two-view hypotheses, §8g re-assignment and merging, §8f again
    if cfg.seed:
        groups, gvalid = _seed_stage(K, R, t, xy, mask, d, groups, gvalid, tau, cfg, miss)
    if cfg.reassign:
        groups, gvalid = reassign_groups(K, R, t, xy, mask, groups, gvalid, tau, cfg)
        groups, gvalid = _compact([groups[g] for g in np.flatnonzero(gvalid)], G, M)
    if cfg.seed and cfg.reassign:
        groups, gvalid = _seed_stage(K, R, t, xy, mask, d, groups, gvalid, tau, cfg, miss)
    if cfg.recover or cfg.regroup or cfg.seed or cfg.reassign:
        pts, bpe, err = group_bpe(K, R, t, xy, groups, gvalid)
        if getattr(cfg, "support_filter", False):  # §8d on the grown and regrouped groups
            keep = support_keep(K, R, t, xy, mask, groups, gvalid, pts, tau, cfg)
            groups[~keep] = -1
            gvalid = keep
    if getattr(cfg, "detach_ambiguous", False):  # §8h
        groups = detach_ambiguous(K, R, t, xy, mask, groups, gvalid, tau, cfg.ambiguous_frac)
        pts, bpe, err = group_bpe(K, R, t, xy, groups, gvalid)
    stages["labels_recovered"] = _group_labels(groups, gvalid, M, P)

    # §12 validity gate
    changed = groups.copy()
    groups, gvalid, pts = validity_gate(
        K, R, t, xy, groups, gvalid, pts, tau, cfg.max_err_frac, cfg.min_parallax_deg
    )
    groups, gvalid, _ = dissolve_ambiguous(K, R, t, d, groups, gvalid, pts, tau)
    for g in np.flatnonzero(gvalid):
        if (changed[g] != groups[g]).any():  # members detached: BPE and error of the new point
            r = np.linalg.norm(
                project(K, R, t, pts[g])
                - np.array(
                    [xy[m, groups[g, m]] if groups[g, m] >= 0 else [0.0, 0.0] for m in range(M)]
                ),
                axis=1,
            )[groups[g] >= 0]
            bpe[g], err[g] = np.mean(r**2), np.mean(r)
    stages["labels_gate"] = _group_labels(groups, gvalid, M, P)

    # §11 output: valid groups first, in the order of §5
    order = np.flatnonzero(gvalid)
    k = len(order)
    res = dict(
        labels=np.full((M, P), -1, dtype=np.int64),
        groups=np.full((G, M), -1, dtype=np.int64),
        valid=np.zeros(G, bool),
        points3d=np.zeros((G, 3)),
        bpe=np.zeros(G),
        err_px=np.zeros(G),
        n_views=np.zeros(G, dtype=np.int64),
        num_groups=k,
        sigma_px=sigma_px,
        tau_px=tau,
        sigma_fallback=sigma_fallback,
    )
    for new, g in enumerate(order):
        res["groups"][new] = groups[g]
        res["valid"][new] = True
        res["points3d"][new] = pts[g]
        res["bpe"][new] = bpe[g]
        res["err_px"][new] = err[g]
        res["n_views"][new] = int((groups[g] >= 0).sum())
        for m in range(M):
            if groups[g, m] >= 0:
                res["labels"][m, groups[g, m]] = new
    if return_stages:
        res["stages"] = stages
    return res


# ----------------------------------------------------------------------------- scenes


def look_at(center, target=(0.0, 0.0, 0.0), up=(0.0, 0.0, 1.0)):
    """World→camera ``R, t`` of a camera at ``center`` looking at ``target`` (+z forward)."""
    center = np.asarray(center, np.float64)
    z = np.asarray(target, np.float64) - center
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, np.float64))
    if np.linalg.norm(x) < 1e-8:
        x = np.cross(z, np.array([1.0, 0.0, 0.0]))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    assert np.linalg.det(R) > 0
    return R, -R @ center


def make_rig(M, rng, radius=3.0, focal=500.0, size=(640, 480), negative_k=(0,)):
    """M cameras on a ring-ish arc at ~``radius`` around the origin looking at it; the views
    in ``negative_k`` get ``K`` multiplied by -1 (K[2,2] = -1, OpenMVG style)."""
    K = np.zeros((M, 3, 3))
    R = np.zeros((M, 3, 3))
    t = np.zeros((M, 3))
    for m in range(M):
        az = 2 * np.pi * m / M + rng.uniform(-0.2, 0.2)
        el = rng.uniform(0.2, 0.7)
        r = radius * rng.uniform(0.9, 1.1)
        c = r * np.array([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), np.sin(el)])
        R[m], t[m] = look_at(c, target=rng.uniform(-0.1, 0.1, 3))
        f = focal * rng.uniform(0.9, 1.1)
        cx, cy = size[0] / 2 + rng.uniform(-5, 5), size[1] / 2
        K[m] = [[f, rng.uniform(-1, 1), cx], [0, f * rng.uniform(0.98, 1.02), cy], [0, 0, 1]]
        if m in negative_k:
            K[m] = -K[m]
    return K, R, t


def make_scene(K, R, t, n_points, rng, sigma=0.0, P=None, drop=0.0, clutter=0, shuffle=True):
    """Random points in the unit box ``[-0.5, 0.5]³``, projected (noise ``sigma``), each
    detection dropped with probability ``drop`` (a point keeps ≥ 2 views), ``clutter``
    uniform false points per view (in the image), slots shuffled per view.

    Returns ``xy (M, P, 2)``, ``mask (M, P)``, ``instance (M, P)`` (-1 padding/clutter),
    ``X (n_points, 3)``. Padded slots hold garbage-free zeros.
    """
    M = K.shape[0]
    X = rng.uniform(-0.5, 0.5, (n_points, 3))
    vis = rng.uniform(size=(n_points, M)) >= drop
    for p in range(n_points):
        while vis[p].sum() < 2:
            vis[p, rng.integers(M)] = True
    P = P or n_points + clutter
    xy = np.zeros((M, P, 2))
    mask = np.zeros((M, P), bool)
    inst = np.full((M, P), -1, dtype=np.int64)
    for m in range(M):
        dets = []
        for p in range(n_points):
            if vis[p, m]:
                dets.append((project(K[m : m + 1], R[m : m + 1], t[m : m + 1], X[p])[0], p))
        for _ in range(clutter):
            dets.append((rng.uniform([0, 0], [640, 480]), -1))
        assert len(dets) <= P
        slots = rng.permutation(P)[: len(dets)] if shuffle else np.arange(len(dets))
        for (pix, p), s in zip(dets, slots):
            xy[m, s] = pix + (sigma * rng.standard_normal(2) if p >= 0 else 0.0)
            mask[m, s] = True
            inst[m, s] = p
    return xy, mask, inst, X
