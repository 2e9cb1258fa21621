"""Kind ``grasp_tta``: GraspTTA and M-GraspTTA (paper section 5.1): a grasp generator's coarse grasps,
then the test-time adaptation of their parameters (:mod:`tohgs.grasps.tta`). F-GraspTTA filters its
predictions (kind ``filtered``, :mod:`tohgs.methods.filtered`).

Keys of the method block:

- ``cvae``: a grasp component (GraspCVAE, :mod:`tohgs.models.grasp_cvae`; any grasp generator works);
- ``contact_net``: a ``hand_contact`` component (ContactNet) for the adaptation's consistency term;
- ``contact``: what the generator reads as its contact channel: ``none`` (GraspTTA, object-centric), a
  contact component (M-GraspTTA TA: ContactDiffuser's maps) or ``ground_truth`` (M-GraspTTA GT: the
  configuration's own task-grasp maps: those the ``Dataset`` row evaluates, :func:`tohgs.methods.base.ground_truth_pick`).

The prediction settings ``tta`` (:class:`tohgs.grasps.tta.TTASettings`) are this kind's. Per
configuration the mean energy before and after the adaptation is recorded. Where the generator reads no
map, the stored contact maps are ContactNet's for the adapted hands (what the adaptation aimed at).
"""

from __future__ import annotations

import time

import numpy as np
import torch

from tohgs.config import settings_from
from tohgs.grasps.tta import TTASettings, adapt
from tohgs.methods.base import Method, Prediction
from tohgs.methods.contact_grasp import GROUND_TRUTH, NO_CONTACT, smooth_contact


class GraspTTA(Method):
    """A generator's grasps, adapted (module docstring)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.require_hand("GraspTTA adapts hands")
        self.generator = self.model("cvae")
        self.contact_net = self.model("contact_net")
        src = self.cfg["contact"]
        self.contact_model = None if src in (NO_CONTACT, GROUND_TRUTH) else self.model("contact")
        self.tta = settings_from(TTASettings, self.settings.tta)
        self.alpha = float(getattr(self.contact_net, "alpha_contact", 100.0))

    def contact_maps(self, batch, shard, row, generator) -> torch.Tensor | None:
        """(S, N) the maps the generator reads: none, a contact component's or the ground truth's (an
        empty tensor where the configuration has no task grasp)."""
        s, src = self.settings, self.cfg["contact"]
        if src == NO_CONTACT:
            return None
        if src == GROUND_TRUTH:
            ids = self.ground_truth(shard, row)
            if len(ids) == 0:
                return torch.zeros(0)
            return torch.as_tensor(shard.contact[ids], device=batch.device)
        contact = self.contact_model.sample_contact(batch, s.sampler, s.steps, generator)
        return smooth_contact(batch.points[0], contact, s.contact_smoothing)

    def predict(self, batch, shard, row, generator, rng) -> Prediction | None:
        s = self.settings
        t0 = time.perf_counter()
        contact = self.contact_maps(batch, shard, row, generator)
        if contact is not None and contact.numel() == 0:
            return None
        if contact is not None:
            batch = batch.with_contact(contact)
        t1 = time.perf_counter()
        coarse = self.generator.sample_grasps(batch, s.sampler, s.steps, generator, s.guidance)
        t2 = time.perf_counter()
        grasp, history = adapt(self.hand, coarse, batch.points, self.contact_net, self.alpha, self.tta)
        t3 = time.perf_counter()
        if contact is None:  # what the adaptation aimed at: ContactNet's map for the adapted hand
            with torch.no_grad():
                contact = self.contact_net.predict_map(batch.points, self.hand(grasp).vertices)
        seconds = {"contact_map": t1 - t0, "grasp": t2 - t1, "adaptation": t3 - t2}
        info = {"energy_start": history["energy"][0], "energy_end": history["energy"][-1]}
        return Prediction(contact.cpu().numpy().astype(np.float32), grasp.cpu().numpy().astype(np.float64),
                          seconds, info=info)


METHOD = GraspTTA
