"""The jitted JAX pipeline against the plain NumPy oracle (tests/oracle.py) on small scenes.

float64 (``jax.enable_x64``): labels, groups, valid, n_views identical (§11 fixes the
numbering), points3d / bpe / err_px to a tight tolerance. float32: identical groups on at
least 95 % of the scenes. On a float64 mismatch the message names the first stage that
differs, found by re-running both sides with the later stages switched off.

One known source of disagreement that is not an implementation bug: with σ = 0, an IQR
without guards and without the absolute floor (``iqr_floor_px = 0``), node scores are
round-off (~1e-13 px in float64, ~1e-4 px in float32) and the IQR fences act on round-off
noise, so which node (if any) is dropped depends on the summation order. For those
scene/config pairs (``_roundoff_iqr``) a mismatch is accepted when every group of the
pipeline lies inside one group of the oracle's §5 table (before the IQR: the graph stages
must still agree exactly). The presets never hit this (paper: 1 px floor; reference: guards).

Compilations dominate the run time (~5–9 s each on 2 cores), so the scenes of one test
share one array shape and the variants bundle several structural branches per config.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from oracle import make_rig, make_scene, oracle_associate

import cdog_jax
from cdog_jax import Config

try:
    from cdog_jax.geometry import Rig
except ImportError:  # public export not there yet
    from cdog_jax.geometry._camera import Rig

P_CAP = 16  # one slot capacity for every scene: fewer shapes, fewer compilations


def _scenes(seed, count, M, sigmas, empty_views=(0,), drop=(0.0, 0.15, 0.3), one_point_view=False):
    """``count`` scenes on ``M``-view rigs (one array shape: each compilation takes seconds),
    3–13 points, σ cycling through ``sigmas``, missed detections, 0–2 clutter points per
    view; ``empty_views`` cycles how many views get no detection (fewer views with the same
    shape), ``one_point_view`` leaves a single detection in view 0 of every 7th scene."""
    rng = np.random.default_rng(seed)
    scenes = []
    for k in range(count):
        K, R, t = make_rig(M, rng, negative_k=(k % M,))
        clutter = int(rng.integers(0, 3))
        n = int(rng.integers(3, P_CAP - clutter - 2))
        sigma = sigmas[k % len(sigmas)]
        p_drop = float(drop[(k // len(sigmas)) % len(drop)])
        xy, mask, _, _ = make_scene(
            K, R, t, n, rng, sigma=sigma, P=P_CAP, drop=p_drop, clutter=clutter
        )
        n_empty = empty_views[k % len(empty_views)]
        mask[M - n_empty :] = False
        extra = f",{M - n_empty} active views" if n_empty else ""
        if one_point_view and k % 7 == 6:
            keep = np.flatnonzero(mask[0])[:1]
            mask[0] = False
            mask[0, keep] = True
            extra += ",1-point view"
        xy = np.where(mask[..., None], xy, 0.0)
        name = f"scene{seed}.{k}(M={M},n={n},σ={sigma},clutter={clutter},drop={p_drop}{extra})"
        scenes.append(dict(name=name, K=K, R=R, t=t, xy=xy, mask=mask, sigma=sigma))
    return scenes


# float64 presets: 6-view rigs with 0–3 views emptied (3–6 active views).
SCENES = _scenes(
    2024, 32, 6, (0.0, 0.5, 2.0, 4.0), empty_views=(0, 0, 1, 2, 3), one_point_view=True
)
# float64 variants: 4-view rigs, σ > 0 (sigma="auto" needs noise).
VARIANT_SCENES = _scenes(77, 12, 4, (0.5, 2.0, 4.0), empty_views=(0,), drop=(0.2,))
# float32 presets: 3-view rigs.
F32_SCENES = _scenes(5, 24, 3, (0.0, 0.5, 2.0, 4.0), empty_views=(0,))

PRESETS = {
    "paper": Config.paper(),
    "reference": Config.reference(),
    "extended": Config.extended(),
    "best": Config.best(),
}
# Every structural branch the presets leave out, in as few compilations as possible.
# (bpe_filter off is the reference preset; prune_scope "conflicts" too.)
VARIANTS = {
    "paper_union_prune_none_auto_sigma": Config.paper(
        adjacency="union", prune_scope="none", sigma_mode="auto"
    ),
    "reference_union_bpe_filter": Config.reference(adjacency="union", bpe_filter=True),
    "paper_recover_only": Config.paper(recover=True),
    "paper_regroup_no_iqr": Config.paper(regroup=True, iqr=False),
    # seeding needs many leftovers (paper() leaves them), 3-member seeds, fewer rounds
    "paper_seed3_reassign2": Config.paper(
        seed=True, seed_min_views=3, reassign=True, reassign_iters=2
    ),
}


# Numeric thresholds are traced: these reuse the presets' compilations (same structure).
NUMERIC_VARIANTS = {
    "paper_no_iqr_floor_delta055_alpha3": Config.paper(
        iqr_floor_px=0.0, delta=0.55, alpha_tau=3.0, jump_kappa=5.0
    ),
    "reference_tau4_guards2_frac08": Config.reference(
        tau_min_px=4.0, iqr_alpha=2.0, iqr_min_px=2.0, second_frac=0.8
    ),
    "best_seed15_reassign15": Config.best(seed_frac=1.5, reassign_frac=1.5),
}


def _associate_fn():
    fn = getattr(cdog_jax, "associate", None)
    if fn is None:
        pytest.fail("cdog_jax.associate does not exist yet (the pipeline is not written)")
    return fn


def _sigma_arg(cfg, sigma):
    return "auto" if cfg.sigma_mode == "auto" else sigma


def run_jax(scene, cfg, dtype):
    """The pipeline on one scene, results as numpy. ``dtype`` float64 runs under x64."""
    associate = _associate_fn()

    def go():
        rig = Rig(
            jnp.asarray(scene["K"], dtype),
            jnp.asarray(scene["R"], dtype),
            jnp.asarray(scene["t"], dtype),
        )
        res = associate(
            rig,
            jnp.asarray(scene["xy"], dtype),
            jnp.asarray(scene["mask"]),
            method=cfg,
            sigma=_sigma_arg(cfg, scene["sigma"]),
        )
        return {
            k: np.asarray(getattr(res, k))
            for k in (
                "labels",
                "groups",
                "valid",
                "points3d",
                "bpe",
                "err_px",
                "n_views",
                "num_groups",
                "sigma_px",
                "tau_px",
            )
        }

    if dtype == np.float64:
        with jax.enable_x64(True):
            return go()
    return go()


_ORACLE_CACHE = {}


def run_oracle(scene, cfg):
    key = (scene["name"], cfg)
    if key not in _ORACLE_CACHE:
        _ORACLE_CACHE[key] = _run_oracle(scene, cfg)
    return _ORACLE_CACHE[key]


def _run_oracle(scene, cfg):
    return oracle_associate(
        scene["K"],
        scene["R"],
        scene["t"],
        scene["xy"],
        scene["mask"],
        cfg,
        sigma=_sigma_arg(cfg, scene["sigma"]),
        return_stages=True,
    )


def run_oracle_stages(scene, cfg):
    return run_oracle(scene, cfg)["stages"]


def _roundoff_iqr(cfg, scene):
    """IQR fences acting on round-off scores: σ = 0 without the 1 px floor or the guards."""
    floor = getattr(cfg, "iqr_floor_px", 0.0)
    return cfg.iqr and not cfg.iqr_guards and floor <= 0 and scene["sigma"] == 0.0


def _same_partition(a, b):
    """Labels equal up to renumbering of the group ids."""
    if ((a < 0) != (b < 0)).any():
        return False
    pairs = set(zip(a[a >= 0].tolist(), b[b >= 0].tolist()))
    return len(pairs) == len({p for p, _ in pairs}) == len({q for _, q in pairs})


def compare(jx, orc, tight=True):
    """Mismatch descriptions (empty when the results agree)."""
    msgs = []
    k = int(orc["num_groups"])
    if int(jx["num_groups"]) != k:
        msgs.append(f"num_groups jax={int(jx['num_groups'])} oracle={k}")
    if not np.array_equal(jx["labels"], orc["labels"]):
        how = (
            "same partition, other numbering"
            if _same_partition(jx["labels"], orc["labels"])
            else "partition"
        )
        diff = np.argwhere(jx["labels"] != orc["labels"])
        at = tuple(diff.T)
        msgs.append(
            f"labels differ ({how}) at (view, slot) {diff.tolist()[:8]}: "
            f"jax={jx['labels'][at].tolist()[:8]} oracle={orc['labels'][at].tolist()[:8]}"
        )
    for key in ("groups", "valid", "n_views"):
        if jx[key].shape != orc[key].shape:
            msgs.append(f"{key} shape jax={jx[key].shape} oracle={orc[key].shape}")
        elif not np.array_equal(jx[key], orc[key]):
            rows = np.flatnonzero((jx[key] != orc[key]).reshape(len(orc[key]), -1).any(1))
            msgs.append(
                f"{key} differ at rows {rows.tolist()[:6]}: jax={jx[key][rows[:3]].tolist()} "
                f"oracle={orc[key][rows[:3]].tolist()}"
            )
    if tight and not msgs:
        tols = dict(points3d=(1e-7, 1e-7), bpe=(1e-6, 1e-9), err_px=(1e-6, 1e-8))
        for key, (rtol, atol) in tols.items():
            a, b = jx[key][:k], orc[key][:k]
            if not np.allclose(a, b, rtol=rtol, atol=atol):
                worst = int(np.argmax(np.abs(a - b).reshape(k, -1).max(1)))
                msgs.append(f"{key} differ, worst group {worst}: jax={a[worst]} oracle={b[worst]}")
        for key in ("sigma_px", "tau_px"):
            if not np.allclose(jx[key], orc[key], rtol=1e-6, atol=1e-9):
                msgs.append(f"{key} jax={float(jx[key])} oracle={float(orc[key])}")
    return msgs


def stage_ladder(cfg):
    """Configs switching the later stages on one at a time (graph only, +IQR, +second, +BPE,
    +recovery and regrouping, +seeding and re-assignment)."""
    late = dict(recover=False, regroup=False, seed=False, reassign=False)
    rungs = [
        ("graph §1-5", cfg.replace(iqr=False, second_association=False, bpe_filter=False, **late))
    ]
    if cfg.iqr:
        rungs.append(("+IQR §6", cfg.replace(second_association=False, bpe_filter=False, **late)))
    if cfg.second_association:
        rungs.append(("+second §7", cfg.replace(bpe_filter=False, **late)))
    if cfg.bpe_filter:
        rungs.append(("+BPE filter §8", cfg.replace(**late)))
    if cfg.recover or cfg.regroup:
        rungs.append(("+recovery, regrouping §8b-c", cfg.replace(seed=False, reassign=False)))
    if cfg.seed or cfg.reassign:
        rungs.append(("+seeding, re-assignment §8f-g", cfg))
    return rungs


def diagnose(scene, cfg):
    """The first stage whose result differs between the pipeline and the oracle (float64)."""
    for name, c in stage_ladder(cfg):
        msgs = compare(run_jax(scene, c, np.float64), run_oracle(scene, c), tight=False)
        if msgs:
            return f"first differing stage: {name}"
    return "every stage agrees on groups (difference in values only)"


def _groups_within(jx, stage_labels):
    """Every group of the pipeline lies inside one group of the oracle's ``stage_labels``."""
    for g in range(int(jx["num_groups"])):
        ids = {int(stage_labels[m, s]) for m, s in enumerate(jx["groups"][g]) if s >= 0}
        if len(ids) != 1 or -1 in ids:
            return False
    return True


def _check_float64(scenes, cfg):
    failures, roundoff = [], 0
    for scene in scenes:
        jx, orc = run_jax(scene, cfg, np.float64), run_oracle(scene, cfg)
        msgs = compare(jx, orc)
        if msgs and _roundoff_iqr(cfg, scene):
            # IQR on round-off scores: only require the pipeline's groups to be inside the
            # oracle's groups before the IQR (the graph stages are exact).
            split = run_oracle_stages(scene, cfg)["labels_split"]
            if _groups_within(jx, split):
                roundoff += 1
                continue
            msgs.append("a group is not inside an oracle group of §5 (before the IQR)")
        if msgs:
            failures.append(f"{scene['name']}: {diagnose(scene, cfg)}\n    " + "\n    ".join(msgs))
    assert not failures, f"{len(failures)}/{len(scenes)} scenes differ:\n" + "\n".join(failures)
    return roundoff


@pytest.mark.parametrize("preset", sorted(PRESETS))
def test_float64_presets_match_oracle(preset):
    _check_float64(SCENES, PRESETS[preset])


@pytest.mark.parametrize("variant", sorted(NUMERIC_VARIANTS))
def test_float64_numeric_variants_match_oracle(variant):
    _check_float64(SCENES, NUMERIC_VARIANTS[variant])


@pytest.mark.parametrize("variant", sorted(VARIANTS))
def test_float64_variants_match_oracle(variant):
    _check_float64(VARIANT_SCENES, VARIANTS[variant])


@pytest.mark.parametrize("preset", sorted(PRESETS))
def test_float32_presets_mostly_match_oracle(preset):
    cfg = PRESETS[preset]
    scenes = F32_SCENES
    bad = []
    for scene in scenes:
        jx = run_jax(scene, cfg, np.float32)
        msgs = compare(jx, run_oracle(scene, cfg), tight=False)
        if (
            msgs
            and _roundoff_iqr(cfg, scene)
            and _groups_within(jx, run_oracle_stages(scene, cfg)["labels_split"])
        ):
            continue
        if msgs:
            bad.append(f"{scene['name']}: " + "; ".join(msgs))
    assert len(bad) <= 0.05 * len(scenes), (
        f"{len(bad)}/{len(scenes)} scenes differ in float32:\n" + "\n".join(bad)
    )
