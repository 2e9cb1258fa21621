"""Kind ``flex``: FLEX re-purposed for hands (paper section 5.1): per test configuration, grasps found by
optimisation over a learned pose prior's latent and the global pose, kept out of the scene cloud at the
initial and the goal pose (:mod:`tohgs.grasps.flex`).

Key of the method block: ``prior``, a ``pose_prior`` component (:mod:`tohgs.models.pose_prior`). The
prediction setting ``flex`` (:class:`tohgs.grasps.flex.FlexSettings`) is this kind's. The stored contact
maps are those the returned hands make on the object (the map shards' map, at their ``alpha_contact``);
per configuration the mean energy of the first and of the last step is recorded.
"""

from __future__ import annotations

import time

import numpy as np
import torch

from tohgs.config import settings_from
from tohgs.geometry.hand_object import contact_values
from tohgs.grasps.flex import FlexSettings, optimise
from tohgs.methods.base import Method, Prediction


class Flex(Method):
    """The optimisation per configuration (module docstring)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.require_hand("FLEX poses hands")
        self.prior = self.model("prior")
        self.flex = settings_from(FlexSettings, self.settings.flex)
        if self.flex.survivors() < self.settings.samples:
            raise ValueError(f"method {self.name!r}: prediction.flex keeps {self.flex.survivors()} of its "
                             f"{self.flex.batch} candidates, fewer than the {self.settings.samples} samples: raise flex.batch")

    def predict(self, batch, shard, row, generator, rng) -> Prediction | None:
        t0 = time.perf_counter()
        grasp, history = optimise(self.hand, self.prior, batch.points[0], batch.normals[0], batch.scene[0],
                                  batch.scene_normals[0], batch.goal_transform[0], self.settings.samples, self.flex,
                                  generator)
        t1 = time.perf_counter()
        with torch.no_grad():
            contact, _ = contact_values(batch.points, self.hand(grasp).vertices, float(shard.attrs.get("alpha_contact", 100.0)))
        info = {"energy_start": history["energy"][0], "energy_end": history["energy"][-1]} if history else {}
        return Prediction(contact.cpu().numpy().astype(np.float32), grasp.cpu().numpy().astype(np.float64),
                          {"optimisation": t1 - t0}, info=info)


METHOD = Flex
