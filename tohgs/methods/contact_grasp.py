"""Kind ``contact_grasp`` (paper section 4.4): a contact source, then a grasp generator on its maps.

Keys of the method block: ``contact``, a contact component (``sample_contact``: ContactDiffuser, ...),
``ground_truth`` (the configuration's own task-grasp maps, cycled to S: the paper's GT-contact rows) or
``none`` (a generator that reads the object alone: SceneDiffuser), and ``grasp``, a grasp component
(``sample_grasps``: GraspDiffuser, ...). Per test configuration: S contact maps, one grasp per map. A
component's maps may be smoothed (``settings.contact_smoothing``: each value the mean over its k nearest
points); ground-truth maps never are. Without maps, the stored maps are those the sampled hands make on
the object (the map shards' contact map, at their ``alpha_contact``). With ``settings.steer`` (beyond the
paper) the grasp generator's sampling is guided out of the scene at both poses (:mod:`tohgs.models.guidance`).
"""

from __future__ import annotations

import time

import numpy as np
import torch

from tohgs.geometry.hand_object import contact_values
from tohgs.methods.base import Method, Prediction, gt_rows
from tohgs.models.guidance import GuidanceSettings

GROUND_TRUTH = "ground_truth"
NO_CONTACT = "none"


def smooth_contact(points: torch.Tensor, contact: torch.Tensor, k: int) -> torch.Tensor:
    """Each contact value replaced by the mean over its ``k`` nearest points (itself among them).

    Args:
        points: (N, 3) object points, m.
        contact: (S, N) contact maps of those points, in [0, 1].
        k: neighbours; ``k <= 1`` returns ``contact`` unchanged.

    Returns:
        (S, N) smoothed maps, in [0, 1].
    """
    if k <= 1:
        return contact
    k = min(k, points.shape[0])
    nn = torch.cdist(points, points).topk(k, largest=False).indices  # (N, k), the point itself first
    return contact[:, nn].mean(-1)


class ContactGrasp(Method):
    """Contact maps from a component or the ground truth, then one grasp per map."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        src = self.cfg["contact"]
        self.contact_model = None if src in (GROUND_TRUTH, NO_CONTACT) else self.model("contact")
        self.grasp_model = self.model("grasp")
        reads_maps = getattr(getattr(self.grasp_model, "cfg", None), "contact_input", True)
        if src == NO_CONTACT and reads_maps:
            raise ValueError(f"method {self.name!r}: contact none, but its grasp model {self.cfg['grasp']!r} reads "
                             "contact maps (a grasp_diffuser with contact_input: false reads the object alone)")
        if src == NO_CONTACT and self.hand is None:
            raise ValueError(f"method {self.name!r}: without maps the stored maps are the hands'; the job needs the hand model")
        self.steer = GuidanceSettings(**self.settings.steer)
        if self.steer.active:
            self.require_hand("guided sampling (settings.steer) poses hands")

    def _steer(self) -> dict:
        """The guidance arguments of ``sample_grasps``: none unless ``settings.steer`` is active (a grasp
        model without guidance, e.g. a CVAE, is then never asked for it)."""
        return {"steer": self.steer, "hand": self.hand} if self.steer.active else {}

    def predict(self, batch, shard, row, generator, rng) -> Prediction | None:
        s = self.settings
        t0 = time.perf_counter()
        if self.cfg["contact"] == NO_CONTACT:
            grasp = self.grasp_model.sample_grasps(batch, s.sampler, s.steps, generator, s.guidance, **self._steer())
            t1 = time.perf_counter()
            with torch.no_grad():
                contact, _ = contact_values(batch.points, self.hand(grasp).vertices, float(shard.attrs.get("alpha_contact", 100.0)))
            return Prediction(contact.cpu().numpy().astype(np.float32), grasp.cpu().numpy().astype(np.float64),
                              {"grasp": t1 - t0, "contact_map": time.perf_counter() - t1})
        if self.contact_model is not None:
            contact = self.contact_model.sample_contact(batch, s.sampler, s.steps, generator)
            contact = smooth_contact(batch.points[0], contact, s.contact_smoothing)
        else:
            ids = gt_rows(shard, row)
            if len(ids) == 0:
                return None
            contact = torch.as_tensor(shard.contact[ids[np.arange(s.samples) % len(ids)]], device=batch.device)
        t1 = time.perf_counter()
        grasp = self.grasp_model.sample_grasps(batch.with_contact(contact), s.sampler, s.steps, generator, s.guidance,
                                               **self._steer())
        t2 = time.perf_counter()
        return Prediction(contact.cpu().numpy().astype(np.float32), grasp.cpu().numpy().astype(np.float64),
                          {"contact_map": t1 - t0, "grasp": t2 - t1})


METHOD = ContactGrasp
