"""Cameras from associations, above the association methods: a joint refinement of cameras
and points (``refine_rig``), association alternated with it (``calibrate``), a similarity
alignment of rigs and their errors for evaluation, and the bundle projection error (BPE) as a
differentiable loss. Needs optimistix, a large import: ``import cdog_jax`` does not load
this package."""

from ._alignment import RigErrors as RigErrors, align_rigs as align_rigs, rig_errors as rig_errors
from ._bpe_loss import bpe as bpe, group_bpe as group_bpe
from ._calibrate import CalibrationHistory as CalibrationHistory, calibrate as calibrate
from ._refine_rig import RefineInfo as RefineInfo, refine_rig as refine_rig
