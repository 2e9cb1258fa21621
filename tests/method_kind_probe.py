"""A method kind defined outside the library, for tests/test_method_kind.py: what a new kind is, its module
(a ``Method`` with its ``Settings`` as ``METHOD``) and its schema block (:data:`SCHEMA`, what it adds under
``$defs.method_kinds``). Kind ``lifted``: the Dataset row's grasps, lifted by ``prediction.lift.height``."""

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
    """S of the configuration's ground-truth grasps (as the Dataset row), lifted by ``lift.height``."""

    Settings = LiftedSettings

    def predict(self, batch, shard, row, generator, rng) -> Prediction | None:
        pick = self.ground_truth(shard, row)
        if len(pick) == 0:
            return None
        grasp = shard.grasp[pick].astype(np.float64)
        grasp[:, 2] += self.settings.lift.height
        return Prediction(shard.contact[pick], grasp)


METHOD = Lifted

#: The kind's schema block: its method keys (none), the settings it reads besides every job's, and the
#: settings block it owns (``prediction.lift``).
SCHEMA = {"keys": {}, "settings": ["lift"],
          "blocks": {"lift": {"description": "How far the lifted kind lifts the grasps.", "type": "object",
                              "additionalProperties": False, "default": {},
                              "properties": {"height": {"description": "Lift of the wrist, m.", "type": "number",
                                                        "default": 0.01, "minimum": 0}}}}}
