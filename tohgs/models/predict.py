"""Test-time prediction (paper section 4.4): per test configuration, S contact maps, one grasp per map,
placed at the target's initial pose and carried to its goal pose by ``T_goal T_init^-1``.

The contact maps come from ContactDiffuser (``contact_source="model"``), from the ground-truth task
grasps of the configuration (``"ground_truth"``: the paper's Table 2 / 5 ablations; a configuration's
grasps are cycled to S maps), or from another method's prediction store (a path).
"""

from __future__ import annotations

import logging
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from tohgs.data.maps import MapDataset
from tohgs.data.predictions import read_predictions, write_predictions
from tohgs.grasps.expand import transform_grasp
from tohgs.models.diffusion import sample
from tohgs.models.train import load_model, pick_device

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PredictSettings:
    """``samples`` S per configuration (the paper's 16); sampler ``ddpm`` (all T steps) or ``ddim`` with
    ``steps`` steps; ``seed``; ``device``; GraspDiffuser's classifier-free ``guidance`` scale;
    ``contact_smoothing``, the neighbours over which ContactDiffuser's maps are averaged (0: none)."""

    samples: int = 16
    sampler: str = "ddim"
    steps: int = 50
    seed: int = 0
    threads: int = 1
    device: str = "auto"
    guidance: float = 1.0  # GraspDiffuser's classifier-free guidance scale (1: none; needs cond_dropout)
    contact_smoothing: int = 0  # k of :func:`smooth_contact` for ContactDiffuser's maps (0 or 1: none)


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


def _gt_contacts(shard, c: int, n: int) -> np.ndarray | None:
    rows = np.flatnonzero(shard.grasp_config == c)
    if len(rows) == 0:
        return None
    return shard.contact[rows[np.arange(n) % len(rows)]]


def predict(task: str, method: str, test_shards: list[str | Path], grasp_ckpt: str | Path, contact_source: str,
            settings: dict, out: str | Path, contact_ckpt: str | Path | None = None) -> dict[str, np.ndarray]:
    """Predict S grasps per test configuration of ``task`` and write the store ``out``.

    Args:
        task, method: recorded in the store.
        test_shards: the task's test map shards.
        grasp_ckpt: the GraspDiffuser checkpoint.
        contact_source: ``"model"`` (needs ``contact_ckpt``), ``"ground_truth"``, or a prediction store path.
        settings: a config mapping of :class:`PredictSettings`.
        out: the store to write.
    """
    s = PredictSettings(**settings)
    torch.set_num_threads(max(1, s.threads))
    # PyTorch's inference "fast path" for transformer layers materialises ContactDiffuser's 512 x 512
    # attention; the regular path runs scaled_dot_product_attention and is 1.7x faster per layer on a CPU
    # (same outputs to 1e-6). A process-wide switch: predict runs as its own job.
    torch.backends.mha.set_fastpath_enabled(False)
    device = pick_device(s.device)
    data = MapDataset(test_shards, per="config")
    grasp_model, gck = load_model(grasp_ckpt, device)
    contact_model = None
    other = None
    if contact_source == "model":
        if contact_ckpt is None:
            raise ValueError("contact_source 'model' needs the ContactDiffuser checkpoint")
        contact_model, _ = load_model(contact_ckpt, device)
    elif contact_source != "ground_truth":
        other = read_predictions(contact_source)[0]
        if len(other["object_id"]) != len(data):
            raise ValueError(f"{contact_source}: {len(other['object_id'])} configurations, the test shards have {len(data)}")
    gen = torch.Generator().manual_seed(s.seed)
    wrist = np.asarray(data.shards[0].attrs["hand_wrist"]) if data.shards else np.zeros(3)
    rows = {k: [] for k in ("object_id", "config_index", "contact", "grasp_init", "grasp_goal")}
    vocab = data.shards[0].attrs["objects"] if data.shards else []
    t_contact = t_grasp = 0.0
    skipped = 0
    from tqdm import tqdm

    for i in tqdm(range(len(data)), desc=f"predict {task}/{method}", mininterval=5.0):
        item = data[i]
        shard = data.shards[item["shard"]]
        c = item["row"]
        pts = torch.as_tensor(item["points"], device=device)[None].expand(s.samples, -1, -1)
        nrm = torch.as_tensor(item["normals"], device=device)[None].expand(s.samples, -1, -1)
        t0 = time.perf_counter()
        if contact_model is not None:
            d_i = torch.as_tensor(item["d_init"], device=device)[None].expand(s.samples, -1)
            d_g = torch.as_tensor(item["d_goal"], device=device)[None].expand(s.samples, -1)
            with torch.no_grad():
                cond = contact_model.condition(pts, nrm, d_i, d_g)
            x = sample(lambda xt, tt: contact_model(xt, tt, cond), (s.samples, pts.shape[1]), contact_model.diffusion,
                       s.sampler, s.steps, gen, device)
            contact = smooth_contact(pts[0], (x.clamp(-1, 1) + 1) / 2, s.contact_smoothing).cpu().numpy()
        elif other is not None:
            contact = other["contact"][i][: s.samples]
        else:
            contact = _gt_contacts(shard, c, s.samples)
            if contact is None:
                skipped += 1
                continue
        t_contact += time.perf_counter() - t0
        t0 = time.perf_counter()
        cmap = torch.as_tensor(contact, dtype=torch.float32, device=device)
        with torch.no_grad():
            gcond = grasp_model.condition(pts, nrm, cmap)
        x0 = sample(lambda xt, tt: grasp_model.guided(xt, tt, gcond, s.guidance), (s.samples, grasp_model.dim), grasp_model.diffusion, s.sampler, s.steps,
                    gen, device)
        with torch.no_grad():
            local = grasp_model.decode(x0, gcond).cpu().numpy().astype(np.float64)
        t_grasp += time.perf_counter() - t0
        world = local.copy()
        world[:, :3] += shard.centroid[c]
        goal = transform_grasp(world, shard.goal_transform[c], wrist)
        rows["object_id"].append(int(item["object_id"]))
        rows["config_index"].append(int(item["config_index"]))
        rows["contact"].append(contact.astype(np.float32))
        rows["grasp_init"].append(world.astype(np.float32))
        rows["grasp_goal"].append(goal.astype(np.float32))
    n = len(rows["object_id"])
    if n == 0:  # e.g. ground-truth maps for test configurations that kept no task grasp
        log.warning("%s/%s: no test configuration could be predicted (%d skipped)", task, method, skipped)
    n_points = data.shards[0].points.shape[1] if data.shards else 0
    arrays = {"object_id": np.asarray(rows["object_id"], np.int32), "config_index": np.asarray(rows["config_index"], np.int32),
              "contact": np.stack(rows["contact"]) if n else np.zeros((0, s.samples, n_points), np.float32),
              "grasp_init": np.stack(rows["grasp_init"]) if n else np.zeros((0, s.samples, 51), np.float32),
              "grasp_goal": np.stack(rows["grasp_goal"]) if n else np.zeros((0, s.samples, 51), np.float32)}
    per = max(1, n * s.samples)
    timing = {"seconds_per_contact_map": t_contact / per, "seconds_per_grasp": t_grasp / per}
    write_predictions(arrays, {"task": task, "method": method, "objects": vocab, "contact_source": str(contact_source),
                               "config": asdict(s), "timing": timing, "skipped_configs": skipped,
                               "grasp_checkpoint_loss": gck["loss_curve"][-1]["loss"] if gck.get("loss_curve") else None},
                      out)
    log.info("%s/%s: %d configurations x %d grasps (%d skipped); %.3f s per contact map, %.3f s per grasp (%s, %d steps)",
             task, method, n, s.samples, skipped, timing["seconds_per_contact_map"], timing["seconds_per_grasp"],
             s.sampler, s.steps)
    return arrays
