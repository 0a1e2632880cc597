"""Cameras from associations, above the association methods: a joint refinement of cameras
and points (``refine_rig``), association alternated with it (``calibrate``), a similarity
alignment of rigs and their errors for evaluation, and the bundle projection error (BPE) as a
differentiable loss. Needs optimistix, a large import: ``import cdog_jax`` does not load
this package."""

from ._bpe_loss import bpe as bpe, group_bpe as group_bpe
from ._alignment import RigErrors as RigErrors
from ._alignment import align_rigs as align_rigs
from ._alignment import rig_errors as rig_errors
from ._calibrate import CalibrationHistory as CalibrationHistory
from ._calibrate import calibrate as calibrate
from ._refine_rig import RefineInfo as RefineInfo
from ._refine_rig import refine_rig as refine_rig
