"""Named configurations: DODT, its ablations, and baselines in the spirit of the paper's
Methods I-III.

The baselines are our re-implementations of the ideas of the cited methods with this
library's components; they are not the original authors' code and will not reproduce their
published numbers.

- dodt: the full method (ensemble of U-depth and DBSCAN, feature association, constant
  acceleration filter, point voting, coasting through occlusions).
- dodt+yolo: dodt with the optional learned person detector (YOLO-MAD, dodt.learned) on the
  color image: needs the shipped ONNX model and onnxruntime.
- dodt-no-ensemble: the U-depth detector alone ("w/o Ens" in the paper's Table I).
- dodt-no-fat: centre-distance association and a constant-velocity filter ("w/o FAT").
- dodt-no-coast: the paper's own behaviour of dropping a track as soon as it is missed.
- method-1-umap: U-map (U-depth) detector, centre-distance association, constant-velocity
  filter, velocity threshold only (after Lin et al., the paper's Method I).
- method-2-cluster: point-cloud clustering (DBSCAN), centre-distance association, constant-
  velocity filter, velocity threshold (after Wang et al., Method II).
- method-3-udepth-velocity: U-depth detector, centre-distance association, constant-velocity
  filter, velocity threshold with consistency over frames (after Xu et al. 2022, Method III).

The DODT presets end identification with the motion label (dodt.motion_label); the baselines, other
methods, do not.
"""
from __future__ import annotations

from dataclasses import replace

from dodt.config import (AssociationConfig, DODTConfig, EnsembleConfig, IdentificationConfig, KalmanConfig,
                         LearnedConfig, MotionConfig, TrackConfig)

_CENTER_CV = dict(association=AssociationConfig(method="center"), kalman=KalmanConfig(model="cv"))
_VELOCITY_ONLY = IdentificationConfig(method="velocity", consistency_span=0.0, force_dynamic_span=None)
_NO_COAST = TrackConfig(coast_time=0.0)
_NO_MOTION = MotionConfig(enabled=False)

PRESETS: dict[str, DODTConfig] = {
    "dodt": DODTConfig(name="dodt"),
    "dodt+yolo": DODTConfig(name="dodt+yolo", learned=LearnedConfig(enabled=True)),
    "dodt-no-ensemble": DODTConfig(name="dodt-no-ensemble", ensemble=EnsembleConfig(detectors=("udepth",))),
    "dodt-no-fat": DODTConfig(name="dodt-no-fat", **_CENTER_CV),
    "dodt-no-coast": DODTConfig(name="dodt-no-coast", track=_NO_COAST),
    "method-1-umap": DODTConfig(name="method-1-umap", ensemble=EnsembleConfig(detectors=("udepth",)),
                                identification=_VELOCITY_ONLY, track=_NO_COAST, motion=_NO_MOTION, **_CENTER_CV),
    "method-2-cluster": DODTConfig(name="method-2-cluster", ensemble=EnsembleConfig(detectors=("dbscan",)),
                                   identification=_VELOCITY_ONLY, track=_NO_COAST, motion=_NO_MOTION, **_CENTER_CV),
    "method-3-udepth-velocity": DODTConfig(
        name="method-3-udepth-velocity", ensemble=EnsembleConfig(detectors=("udepth",)),
        identification=replace(_VELOCITY_ONLY, consistency_span=2 / 30), track=_NO_COAST, motion=_NO_MOTION,
        **_CENTER_CV),
}


def preset(name: str) -> DODTConfig:
    try:
        return PRESETS[name]
    except KeyError:
        raise ValueError(f"unknown perception configuration {name!r}; known: {', '.join(PRESETS)}") from None
