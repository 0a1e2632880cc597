"""Chunks of a batch spread over several devices (``cdog_jax/_runtime/devices.py``): the
same results bitwise as on one device; the setting is made only before JAX's first
computation and never by importing the package."""

import argparse
import os
import subprocess
import sys

import numpy as np
from helpers import random_scene, ring_rig

import cdog_jax
from cdog_jax._runtime import devices

SCRIPT = """
import sys
import numpy as np
import jax
from cdog_jax.benchmark import use_cpu_cores
assert use_cpu_cores(count=2) == 2
import cdog_jax
import cdog_jax._associate as associate_module
sys.path.insert(0, sys.argv[2])
from test_devices import live_frames, scenes
assert len(jax.local_devices()) == 2
ran_on = set()  # the devices the association's chunks ran on
call_stored = associate_module.call_stored
def recorded(*args, **kwargs):
    out = call_stored(*args, **kwargs)
    ran_on.update(d.id for d in jax.tree.leaves(out)[0].devices())
    return out
associate_module.call_stored = recorded
rig, xy, mask, classes = scenes()
batch = cdog_jax.associate_batch(rig, xy, mask, method="paper", sigma=1.0, batch_size=2)
assert ran_on == {0, 1}, ran_on
ran_on.clear()  # a rig committed to the first device: the chunks still take both
placed = jax.device_put(rig, jax.local_devices()[0])
again = cdog_jax.associate_batch(placed, xy, mask, method="paper", sigma=1.0, batch_size=2)
assert ran_on == {0, 1}, ran_on
for a, b in zip(vars(again).values(), vars(batch).values()):
    assert np.array_equal(np.asarray(a), np.asarray(b))
classed = cdog_jax.associate_classes(rig, xy, mask, classes, method="paper")
ran_on.clear()
live = live_frames(rig, xy, mask, classes)
assert ran_on == {0, 1}, ran_on
np.savez(sys.argv[1], **{f"batch_{k}": np.asarray(v) for k, v in vars(batch).items()},
         **{f"classes_{k}": np.asarray(v) for k, v in vars(classed.association).items()},
         **{f"live_{k}": v for k, v in live.items()})
"""


def scenes():
    """Five scenes: a batch in chunks of 2 (3 chunks, on alternate devices), and as 5 frames
    × 3 classes, whose σ fit has a row per frame (split over the devices)."""
    rig = ring_rig(4)
    parts = [random_scene(rig, 6, 8, sigma=1.0, seed=s) for s in range(5)]
    xy = np.stack([p[0] for p in parts]).astype(np.float32)  # (5, M, 8, 2)
    mask = np.stack([p[1] for p in parts])
    classes = np.broadcast_to(np.arange(8) % 3, mask.shape).copy()
    return rig, xy, mask, classes


def live_frames(rig, xy, mask, classes) -> dict:
    """The five scenes as frames of a live associator of 3 classes (on two devices, its
    class scenes in two chunks, one per device), each frame's answer as arrays; at 4 slots,
    its one rung (the point is the devices: one rung compiles half the programs)."""
    live = cdog_jax.LiveAssociator(rig, num_classes=3, method="paper", sigma=1.0, slots=4)
    answers = [live.update(xy[f], mask[f], classes=classes[f]) for f in range(len(xy))]
    fields = ("labels", "groups", "points3d", "err_px", "track_id", "group_class")
    return {
        f"{name}_{f}": np.asarray(getattr(answer, name))
        for f, answer in enumerate(answers)
        for name in fields
    }


def test_two_devices_give_the_same_bits_as_one(tmp_path):
    """A batch in chunks, classes and a live associator's frames on two devices: the chunks
    run on both (a chunk's arguments go with its call) and give one device's bits."""
    rig, xy, mask, classes = scenes()
    out = tmp_path / "two.npz"
    # The child inherits this process's XLA flags: the same code generator, the same bits.
    subprocess.run([sys.executable, "-c", SCRIPT, str(out), os.path.dirname(__file__)], check=True)
    two = np.load(out)
    # paper(): the point is the devices, and its programs compile in half the time of best()'s
    batch = cdog_jax.associate_batch(rig, xy, mask, method="paper", sigma=1.0, batch_size=2)
    classed = cdog_jax.associate_classes(rig, xy, mask, classes, method="paper")
    live = live_frames(rig, xy, mask, classes)
    for prefix, result in (
        ("batch_", batch),
        ("classes_", classed.association),
        ("live_", argparse.Namespace(**live)),
    ):
        for name, value in vars(result).items():
            value = np.asarray(value)
            assert two[prefix + name].dtype == value.dtype and np.array_equal(
                two[prefix + name], value
            ), prefix + name


def test_chunks_take_the_devices_in_turn():
    import jax

    count = len(jax.local_devices())
    assert devices.chunk_devices(1) == [None]
    expected = [None] * 3 if count < 2 else [jax.local_devices()[k % count] for k in range(3)]
    assert devices.chunk_devices(3) == expected


def test_importing_the_package_exposes_no_cores():
    code = "import cdog_jax, cdog_jax.cli, jax; print(len(jax.local_devices()))"
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True)
    assert out.stdout.strip() == "1"


def test_a_live_frame_takes_two_chunks_however_many_devices(monkeypatch):
    """The class scenes in two chunks where there are several devices (each device a chunk
    runs on compiles the association), one where there is one or a chunk would hold one."""
    import jax

    rig = ring_rig(4)
    for count, classes, chunk in ((1, 25, 25), (2, 25, 13), (8, 25, 13), (8, 3, 2), (8, 2, 2)):
        monkeypatch.setattr(jax, "local_devices", lambda count=count: [None] * count)
        live = cdog_jax.LiveAssociator(rig, num_classes=classes)
        assert live._scenes_per_chunk == chunk, (count, classes)
