"""Kind ``flex``: FLEX re-purposed for hands (paper section 5.1): per test configuration, grasps found by
optimisation over a learned pose prior's latent and the global pose, kept out of the scene cloud at the
initial and the goal pose (:mod:`tohgs.grasps.flex`).

Key of the method block: ``prior``, a ``pose_prior`` component (:mod:`tohgs.models.pose_prior`). The
prediction setting ``flex`` (:class:`tohgs.grasps.flex.FlexSettings`) is this kind's; the candidates of
``chunk`` configurations are optimised as one batch (the same grasps as one at a time). The stored contact
maps are those the returned hands make on the object (the map shards' map, at their ``alpha_contact``);
per configuration the mean energy of the first and of the last step is recorded.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch

from tohgs.geometry.hand_object import contact_values
from tohgs.grasps.flex import FlexSettings, optimise_many
from tohgs.methods.base import Method, Prediction, Request, SamplingSettings
from tohgs.settings import block


@dataclass(frozen=True)
class FlexMethodSettings(SamplingSettings):
    """Every job's settings and ``flex``, the optimisation's (:class:`tohgs.grasps.flex.FlexSettings`)."""

    flex: FlexSettings = block(FlexSettings)


class Flex(Method):
    """The optimisation per configuration (module docstring)."""

    Settings = FlexMethodSettings

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.require_hand("FLEX poses hands")
        self.prior = self.model("prior")
        self.flex = self.settings.flex
        if self.flex.survivors() < self.settings.samples:
            raise ValueError(f"method {self.name!r}: prediction.flex keeps {self.flex.survivors()} of its "
                             f"{self.flex.batch} candidates, fewer than the {self.settings.samples} samples: raise flex.batch")

    def predict(self, batch, shard, row, generator, rng) -> Prediction | None:
        return self.predict_many([Request(batch, shard, row, generator, rng)])[0]

    def predict_many(self, requests: list[Request]) -> list[Prediction | None]:
        """The candidates of every configuration optimised as one batch
        (:func:`tohgs.grasps.flex.optimise_many`: each configuration's own starts, drops and best S); the
        time is shared equally among the configurations."""
        if not requests:
            return []
        t0 = time.perf_counter()
        first = [r.batch for r in requests]
        grasp, histories = optimise_many(
            self.hand, self.prior, *(torch.stack([getattr(b, f)[0] for b in first])
                                     for f in ("points", "normals", "scene", "scene_normals", "goal_transform")),
            self.settings.samples, self.flex, [r.generator for r in requests])
        share = (time.perf_counter() - t0) / len(requests)
        out = []
        for r, g, history in zip(requests, grasp.split(self.settings.samples), histories):
            with torch.no_grad():
                alpha = r.shard.alpha_contact
                contact, _ = contact_values(r.batch.points, self.hand(g).vertices, alpha)
            info = {"energy_start": history["energy"][0], "energy_end": history["energy"][-1]} if history else {}
            out.append(Prediction(contact.cpu().numpy().astype(np.float32), g.cpu().numpy().astype(np.float64),
                                  {"optimisation": share}, info=info))
        return out


METHOD = Flex
