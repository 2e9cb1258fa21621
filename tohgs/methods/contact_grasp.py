"""Kind ``contact_grasp`` (paper section 4.4): a contact source, then a grasp generator on its maps.

Keys of the method block: ``contact``, a contact component (``sample_contact``: ContactDiffuser, ...) or
``ground_truth`` (the configuration's own task-grasp maps, cycled to S: the paper's GT-contact rows), and
``grasp``, a grasp component (``sample_grasps``: GraspDiffuser, ...). Per test configuration: S contact
maps, one grasp per map. A component's maps may be smoothed (``settings.contact_smoothing``: each value
the mean over its k nearest points); ground-truth maps never are.
"""

from __future__ import annotations

import time

import numpy as np
import torch

from tohgs.methods.base import Method, Prediction, gt_rows

GROUND_TRUTH = "ground_truth"


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
        self.contact_model = None if self.cfg["contact"] == GROUND_TRUTH else self.model("contact")
        self.grasp_model = self.model("grasp")

    def predict(self, batch, shard, row, generator, rng) -> Prediction | None:
        s = self.settings
        t0 = time.perf_counter()
        if self.contact_model is not None:
            contact = self.contact_model.sample_contact(batch, s.sampler, s.steps, generator)
            contact = smooth_contact(batch.points[0], contact, s.contact_smoothing)
        else:
            ids = gt_rows(shard, row)
            if len(ids) == 0:
                return None
            contact = torch.as_tensor(shard.contact[ids[np.arange(s.samples) % len(ids)]], device=batch.device)
        t1 = time.perf_counter()
        grasp = self.grasp_model.sample_grasps(batch.with_contact(contact), s.sampler, s.steps, generator, s.guidance)
        t2 = time.perf_counter()
        return Prediction(contact.cpu().numpy().astype(np.float32), grasp.cpu().numpy().astype(np.float64),
                          {"contact_map": t1 - t0, "grasp": t2 - t1})


METHOD = ContactGrasp
