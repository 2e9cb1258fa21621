"""A method kind defined outside the library, for tests/test_method_kind.py: what a new kind is, its module
(a ``Method`` with its ``Settings`` as ``METHOD``) and its schema block (:data:`SCHEMA`, what it declares
under ``$defs.method_kinds``). Kind ``lifted``: another method's grasps (named by its own key ``lifts``),
lifted by ``prediction.lift.height``, with the configuration's ground-truth contact maps (so it reads
ground truth, as its block says)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tohgs.methods.base import Method, Prediction, SamplingSettings
from tohgs.settings import block


@dataclass(frozen=True)
class LiftSettings:
    """``height`` (m) the wrist is lifted by."""

    height: float = 0.01


@dataclass(frozen=True)
class LiftedSettings(SamplingSettings):
    """Every job's settings and the kind's own block, ``lift``."""

    lift: LiftSettings = block(LiftSettings)


class Lifted(Method):
    """The grasps the method ``lifts`` predicted for the configuration, lifted by ``lift.height``, with S of
    the configuration's ground-truth maps (none where it has no task grasp)."""

    Settings = LiftedSettings

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        if self.base is None:
            raise ValueError(f"method {self.name!r}: lifting needs the predictions of {self.cfg['lifts']!r}")
        arrays, attrs = self.base
        self.rows = {(attrs["objects"][int(o)], int(c)): i
                     for i, (o, c) in enumerate(zip(arrays["object_id"], arrays["config_index"]))}

    def predict(self, batch, shard, row, generator, rng) -> Prediction | None:
        key = (shard.attrs["objects"][int(shard.object_id[row])], int(shard.config_index[row]))
        pick = self.ground_truth(shard, row)
        if key not in self.rows or len(pick) == 0:
            return None
        grasp = np.asarray(self.base[0]["grasp_init"][self.rows[key]], np.float64).copy()
        grasp[:, :3] -= shard.centroid[row]  # the network frame
        grasp[:, 2] += self.settings.lift.height
        return Prediction(shard.contact[pick], grasp)


METHOD = Lifted

#: The kind's schema block: its key (``lifts``, another method), that it reads ground truth, the settings
#: it reads besides every job's, and the settings block it owns (``prediction.lift``).
SCHEMA = {"keys": {"lifts": {"role": "method", "description": "The method whose grasps are lifted."}},
          "reads_ground_truth": True, "settings": ["lift"],
          "blocks": {"lift": {"description": "How far the lifted kind lifts the grasps.", "type": "object",
                              "additionalProperties": False, "default": {},
                              "properties": {"height": {"description": "Lift of the wrist, m.", "type": "number",
                                                        "default": 0.01, "minimum": 0}}}}}
