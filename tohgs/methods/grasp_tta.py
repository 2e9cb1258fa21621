"""Kind ``grasp_tta``: GraspTTA and M-GraspTTA (paper section 5.1): a grasp generator's coarse grasps,
then the test-time adaptation of their parameters (:mod:`tohgs.grasps.tta`). F-GraspTTA filters its
predictions (kind ``filtered``, :mod:`tohgs.methods.filtered`).

Keys of the method block:

- ``cvae``: a grasp component (GraspCVAE, :mod:`tohgs.models.grasp_cvae`; any grasp generator works);
- ``contact_net``: a ``hand_contact`` component (ContactNet) for the adaptation's consistency term;
- ``contact``: what the generator reads as its contact channel: ``none`` (GraspTTA, object-centric), a
  contact component (M-GraspTTA TA: ContactDiffuser's maps) or ``ground_truth`` (M-GraspTTA GT: the
  configuration's own task-grasp maps: those the ``Dataset`` row evaluates, :func:`tohgs.methods.base.ground_truth_pick`).

The prediction settings ``tta`` (:class:`tohgs.grasps.tta.TTASettings`) are this kind's. The hands of
``chunk`` configurations are adapted as one batch, each configuration's maps and coarse grasps drawn from
its own streams first (the same grasps as one configuration at a time). Per configuration the mean energy
before and after the adaptation is recorded, and the share of its hands that touch the object (a vertex
within 5 mm of an object point, :data:`tohgs.grasps.tta.TOUCH`) before and after: the adaptation's
penetration term can push a hand that enters the object from one side off it (docs/history.md, issue 39). Where the generator reads no
map, the stored contact maps are ContactNet's for the adapted hands (what the adaptation aimed at).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch

from tohgs.grasps.tta import TTASettings, adapt_many, by_problem, pose_problems
from tohgs.methods.base import ContactSource, GeneratorSettings, Method, Prediction, Request
from tohgs.settings import block


@dataclass(frozen=True)
class GraspTTASettings(GeneratorSettings):
    """A generator's sampling settings and ``tta``, the adaptation's (:class:`tohgs.grasps.tta.TTASettings`)."""

    tta: TTASettings = block(TTASettings)


class GraspTTA(Method):
    """A generator's grasps, adapted (module docstring)."""

    Settings = GraspTTASettings

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.require_hand("GraspTTA adapts hands")
        self.generator = self.model("cvae")
        self.contact_net = self.model("contact_net")
        self.source = ContactSource(self)
        self.tta = self.settings.tta
        self.alpha = float(self.contact_net.alpha_contact)

    def predict(self, batch, shard, row, generator, rng) -> Prediction | None:
        return self.predict_many([Request(batch, shard, row, generator, rng)])[0]

    def predict_many(self, requests: list[Request]) -> list[Prediction | None]:
        """Per configuration (its own streams, in order) the maps and the coarse grasps; then the
        adaptation of every configuration's hands as one batch (:func:`tohgs.grasps.tta.adapt_many`); the
        adaptation's time is shared equally among the configurations."""
        s = self.settings
        staged = []  # (index, batch with its maps, maps or None, coarse grasps, seconds)
        for i, r in enumerate(requests):
            t0 = time.perf_counter()
            contact = self.source.maps(r.batch, r.shard, r.row, r.generator)
            if contact is not None and contact.numel() == 0:
                continue
            batch = r.batch if contact is None else r.batch.with_contact(contact)
            t1 = time.perf_counter()
            coarse = self.generator.sample_grasps(batch, s.sampler, s.steps, r.generator, s.guidance)
            staged.append((i, batch, contact, coarse, {"contact_map": t1 - t0, "grasp": time.perf_counter() - t1}))
        out: list[Prediction | None] = [None] * len(requests)
        if not staged:
            return out
        sizes = [len(c) for _, _, _, c, _ in staged]
        points = torch.cat([b.points for _, b, _, _, _ in staged])
        t2 = time.perf_counter()
        grasp, histories = adapt_many(self.hand, torch.cat([c for _, _, _, c, _ in staged]), points, self.contact_net,
                                      self.alpha, self.tta, sizes)
        share = (time.perf_counter() - t2) / len(staged)
        own = [j for j, (_, _, contact, _, _) in enumerate(staged) if contact is None]
        net_maps: dict[int, torch.Tensor] = {}
        if own:  # what the adaptation aimed at: ContactNet's map for the adapted hand
            rows = torch.cat([torch.arange(sum(sizes[:j]), sum(sizes[:j + 1])) for j in own])
            with torch.no_grad():
                own_sizes = [sizes[j] for j in own]
                verts = pose_problems(self.hand, grasp[rows], own_sizes).vertices
                maps = by_problem(self.contact_net.predict_map, own_sizes, points[rows], verts)
            for j, m in zip(own, maps.split([sizes[j] for j in own])):
                net_maps[j] = m
        for j, ((i, _, contact, _, seconds), g, history) in enumerate(zip(staged, grasp.split(sizes), histories)):
            maps = net_maps[j] if contact is None else contact
            info = {"energy_start": history["energy"][0], "energy_end": history["energy"][-1],
                    "touching_start": history["touching"][0], "touching_end": history["touching"][-1]}
            out[i] = Prediction(maps.cpu().numpy().astype(np.float32), g.cpu().numpy().astype(np.float64),
                                {**seconds, "adaptation": share}, info=info)
        return out


METHOD = GraspTTA
