"""Kind ``contact_grasp`` (paper section 4.4): a contact source, then a grasp generator on its maps.

Keys of the method block: ``contact``, a contact component (``sample_contact``: ContactDiffuser, ...),
``ground_truth`` (the configuration's own task-grasp maps: the same grasps the ``Dataset`` row evaluates,
:func:`tohgs.methods.base.ground_truth_pick`; the paper's GT-contact rows) or
``none`` (a generator that reads the object alone: SceneDiffuser), and ``grasp``, a grasp component
(``sample_grasps``: GraspDiffuser, ...). Per test configuration: S contact maps, one grasp per map. A
component's maps may be smoothed (``settings.contact_smoothing``: each value the mean over its k nearest
points); ground-truth maps never are. Without maps, the stored maps are those the sampled hands make on
the object (the map shards' contact map, at their ``alpha_contact``). With ``settings.steer`` (beyond the
paper) the grasp generator's sampling is guided out of the scene at both poses, the contact diffuser's off the
object points near the scene, and more grasps may be sampled than kept: the best by the same energy, picked
for diversity (:mod:`tohgs.models.guidance`; the stored ``seconds`` gain ``select``, the diagnostics the
candidates' and the kept grasps' mean energy). With ``settings.refine`` (beyond the paper) each sampled hand
is refined against its own map by GraspTTA's adaptation, the map the consistency term's target
(:func:`tohgs.grasps.tta.refine_to_maps`; the stored ``seconds`` gain ``refine``). A grasp model that reads
maps signed by the thumb's contact (a GraspDiffuser with ``thumb_sign``, beyond the paper) is given the ground
truth's maps signed by their own grasps; the stored maps are the unsigned ones.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch

from tohgs.geometry.cloud import even_subset
from tohgs.geometry.hand_object import contact_values
from tohgs.grasps.tta import RefineSettings, refine_to_maps
from tohgs.methods import GROUND_TRUTH
from tohgs.methods.base import ContactSource, GeneratorSettings, Method, Prediction, smooth_contact  # noqa: F401
from tohgs.models.guidance import GuidanceEnergy, GuidanceSettings, select_diverse
from tohgs.settings import block


@dataclass(frozen=True)
class ContactGraspSettings(GeneratorSettings):
    """A generator's sampling settings (``sampler`` and ``steps`` the contact component's), the grasp
    generator's sampler (``grasp_sampler``, ``grasp_steps``: the official ancestral DDPM over all 1000 steps
    by default), ``steer``, the scene-aware guidance of its sampling, and ``refine``, the sampled hands
    refined against their maps (both beyond the paper; every lever off by default). A job is not given
    ``steer`` or ``refine`` while it is at its defaults (their schema blocks' ``x-optional``: so that its
    settings are those of before they existed): the defaults then."""

    grasp_sampler: str = "ddpm"
    grasp_steps: int = 1000
    steer: GuidanceSettings = block(GuidanceSettings, optional=True)
    refine: RefineSettings = block(RefineSettings, optional=True)


class ContactGrasp(Method):
    """Contact maps from a component or the ground truth, then one grasp per map."""

    Settings = ContactGraspSettings

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.source = ContactSource(self)
        self.grasp_model = self.model("grasp")
        if not self.source.reads_maps and self.grasp_model.reads_contact:
            raise ValueError(f"method {self.name!r}: contact none, but its grasp model {self.cfg['grasp']!r} reads "
                             "contact maps (a grasp_diffuser with contact_input: false reads the object alone)")
        if not self.source.reads_maps and self.hand is None:
            raise ValueError(f"method {self.name!r}: without maps the stored maps are the hands'; the job needs the hand model")
        self.steer = self.settings.steer
        if self.steer.active and not self.grasp_model.steerable:
            raise ValueError(f"method {self.name!r}: settings.steer guides a GraspDiffuser's sampling; its grasp "
                             f"model {self.cfg['grasp']!r} is not one (set steer.scale 0)")
        if self.steer.contact_active and not (self.source.model is not None and self.source.model.steerable):
            raise ValueError(f"method {self.name!r}: steer.contact_scale guides a ContactDiffuser's sampling; its "
                             f"contact source {self.source.name!r} is not one (set steer.contact_scale 0)")
        if self.steer.active or self.steer.selects:
            self.require_hand("guided sampling and sample-score-keep (settings.steer) pose hands")
        self.refine = self.settings.refine
        if self.refine.steps:
            self.require_hand("refining hands against their maps (settings.refine) poses them")
        self.signed = bool(getattr(self.grasp_model, "reads_signed_contact", False))
        if self.signed and self.source.name != GROUND_TRUTH:
            raise ValueError(f"method {self.name!r}: its grasp model {self.cfg['grasp']!r} reads contact maps signed by "
                             f"the thumb's contact (thumb_sign), which only the ground truth's grasps give; contact "
                             f"{self.source.name!r} samples maps without it (use contact: {GROUND_TRUTH})")
        if self.signed:
            self.require_hand("maps signed by the thumb's contact pose the ground truth's hands")

    def _steer(self) -> dict:
        """The guidance arguments of ``sample_grasps``: none unless ``settings.steer`` is active (a grasp
        model without guidance, e.g. a CVAE, is then never asked for it)."""
        return {"steer": self.steer, "hand": self.hand} if self.steer.active else {}

    def _select(self, batch, contact: torch.Tensor, grasp: torch.Tensor, keep: int
                ) -> tuple[torch.Tensor, torch.Tensor, dict[str, float]]:
        """``keep`` of the candidates (sample, score, keep): each scored by the guidance energy of its grasp
        (with its own contact map), then :func:`select_diverse`. Returns the kept maps, grasps and the mean
        energy of all candidates and of the kept ones."""
        energy, verts = [], []
        sub = even_subset(self.hand.rest_vertices.shape[0], self.steer.hand_points or 256, grasp.device)
        with torch.no_grad():
            for i in range(0, grasp.shape[0], keep):  # one chunk of S at a time: the energy's distance matrices
                part = batch.index(torch.arange(i, min(i + keep, grasp.shape[0]), device=grasp.device))
                part = part.with_contact(contact[i:i + keep])
                energy.append(GuidanceEnergy.of_batch(self.hand, part, self.steer)(grasp[i:i + keep]))
                verts.append(self.hand(grasp[i:i + keep]).vertices[:, sub])
        energy, verts = torch.cat(energy), torch.cat(verts)
        idx = select_diverse(energy, verts, keep, self.steer.pool)
        info = {"energy_candidates": float(energy.mean()), "energy_kept": float(energy[idx].mean())}
        return contact[idx], grasp[idx], info

    def predict(self, batch, shard, row, generator, rng) -> Prediction | None:
        s = self.settings
        t0 = time.perf_counter()
        if self.steer.selects:  # candidates x S copies of the configuration
            batch = batch.index(torch.zeros(s.samples * self.steer.candidates, dtype=torch.long, device=batch.device))
        if not self.source.reads_maps:
            grasp = self.grasp_model.sample_grasps(batch, s.grasp_sampler, s.grasp_steps, generator, s.guidance,
                                                   **self._steer())
            t1 = time.perf_counter()
            with torch.no_grad():
                contact, _ = contact_values(batch.points, self.hand(grasp).vertices, shard.alpha_contact)
            seconds = {"grasp": t1 - t0, "contact_map": time.perf_counter() - t1}
        else:
            extra = {}
            if self.steer.contact_active:  # guided off the object points near the scene
                extra = {"steer": self.steer, "distance_alpha": shard.alpha_distance}
            contact = self.source.maps(batch, shard, row, generator, signed_by=self.hand if self.signed else None,
                                       **extra)
            if len(contact) == 0:  # ground truth, and the configuration has no task grasp
                return None
            t1 = time.perf_counter()
            grasp = self.grasp_model.sample_grasps(batch.with_contact(contact), s.grasp_sampler, s.grasp_steps, generator,
                                                   s.guidance, **self._steer())
            contact = contact.abs() if self.signed else contact  # stored, selected by: the paper's map
            seconds = {"contact_map": t1 - t0, "grasp": time.perf_counter() - t1}
        if self.refine.steps:  # GraspTTA's adaptation with each hand's own map as the target
            t2 = time.perf_counter()
            grasp, _ = refine_to_maps(self.hand, grasp, batch.points, contact, shard.alpha_contact, self.refine)
            seconds["refine"] = time.perf_counter() - t2
        info = {}
        if self.steer.selects:
            t2 = time.perf_counter()
            contact, grasp, info = self._select(batch, contact, grasp, s.samples)
            seconds["select"] = time.perf_counter() - t2
        return Prediction(contact.cpu().numpy().astype(np.float32), grasp.cpu().numpy().astype(np.float64),
                          seconds, info=info)


METHOD = ContactGrasp
