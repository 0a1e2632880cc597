# %% [markdown]
# # cdog_jax walkthrough: associate, differentiate through the cameras, refine
#
# A notebook in jupytext "percent" format: open it with Jupyter (jupytext) or run it as a
# script, `python experiments/walkthrough.py [--points 40]`. The test suite runs it on a
# small scene so that it never rots.

# %%
from __future__ import annotations

import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import cdog_jax
from cdog_jax.geometry import params_from_rig, rig_from_params
from cdog_jax.metrics import scene_metrics
from cdog_jax.refine import bpe, refine_rig, rig_errors
from cdog_jax.synthetic import default_rig, generate_scene

POINTS = int(sys.argv[sys.argv.index("--points") + 1]) if "--points" in sys.argv else 40

# %% [markdown]
# ## 1. A rig and a scene
# The built-in 10-camera rig (`cdog_jax.io.load_rig` reads your own: EasyVis folder, JSON,
# NPZ). A scene: `POINTS` 3D points, each seen by ≥ 2 cameras, detections with σ = 1 px
# noise, shuffled per view: no descriptors, only geometry.

# %%
rig = default_rig()
scene = generate_scene(jax.random.PRNGKey(0), rig, POINTS, 1.0, capacity=POINTS)
print(f"{rig.num_views} views, {int(scene.mask.sum())} detections of {int(scene.num_points)} points")

# %% [markdown]
# ## 2. Associate
# `associate` checks the inputs, then runs the jitted C-DOG pipeline. The result holds the
# groups (one detection slot per view or -1), their triangulated points and errors.

# %%
result = cdog_jax.associate(rig, scene.xy, scene.mask, sigma=1.0)
metrics = scene_metrics(rig, result, scene)
print(f"{int(result.num_groups)} groups; PG-F1 {float(metrics.pg_f1):.3f}, G-F1 {float(metrics.g_f1):.3f}")

# %% [markdown]
# ## 3. Differentiate the back-projection error w.r.t. the cameras
# Given the groups, the BPE is a smooth function of the camera parameters (rotation vectors,
# translations, focal lengths, principal points, skew).

# %%
params = params_from_rig(rig)


def loss(params):
    return bpe(rig_from_params(params), scene.xy, result.groups, result.valid)


value, grads = jax.value_and_grad(loss)(params)
print(f"BPE {float(value):.3f} px²; d BPE / d focal of view 0: {np.asarray(grads.focal[0])}")

# %% [markdown]
# ## 4. Refine a drifted rig
# Rotate every camera but the first by about 1°, then fit the poses and points jointly to
# the groups found with the true rig (camera 0 and the camera 0–1 distance fix the gauge).
# The focal lengths stay fixed: with one scene they trade against depth.

# %%
key = jax.random.PRNGKey(1)
w = jnp.deg2rad(1.0) * jax.random.normal(key, (rig.num_views, 3)) * (jnp.arange(rig.num_views) > 0).astype(jnp.float32)[:, None]
drifted_rig = rig_from_params(eqx.tree_at(lambda p: p.rotvec, params, params.rotvec + w))
refined, info = refine_rig(
    drifted_rig, scene.xy[None], result.groups[None], result.valid[None], refine_intrinsics=False
)
before = float(jnp.mean(rig_errors(drifted_rig, rig).rotation_deg))
after = float(jnp.mean(rig_errors(refined, rig).rotation_deg))
print(f"BPE {float(info.bpe_before):.2f} → {float(info.bpe_after):.2f} px²; rotation error {before:.3f}° → {after:.3f}°")
assert float(info.bpe_after) < float(info.bpe_before) and after < 0.5 * before
