"""Does a trained GraspDiffuser (or ContactDiffuser) use its condition? Two measurements on training data.

- :func:`shuffled_condition_gap`: the denoising loss with each sample's own condition against the same
  loss with the conditions shuffled across the batch (every sample gets another configuration's object
  and map), at the same timesteps and noise. A network that reads its condition loses accuracy when it is
  handed the wrong one; one that ignores it (it learnt only the marginal of the data) does not.
- :func:`permuted_map_gap`: ContactDiffuser's denoising loss on true maps against the same maps with their
  values permuted across the points (the same condition, timesteps and noise). A permutation keeps every
  value and the map's histogram and breaks only where the values lie: a denoiser that reads only each
  point's own value (per-point marginals) has the same loss on both; one that learnt where contact lies on
  the object, and that it comes in regions, does worse on the permuted maps.
- :func:`contact_fit`: ContactDiffuser's maps against the configuration's ground-truth maps (IoU), and how
  rough they are against the truth (:func:`map_roughness`).
- :func:`representation_fit`: ContactGen's (and ContactCVAE's) sampled representations against the
  configuration's true ones: the contact IoU as :func:`contact_fit`, how alike its samples are (a collapsed
  latent draws one map), the part labels' histogram over the contact points against the truth's, and each
  stage's KL at the end of training.
- :func:`grasp_fit`: grasps sampled from ground-truth contact maps of training configurations, compared
  with the configuration's ground-truth grasps: whether the hand touches the object (some hand vertex within
  ``touch`` of the object cloud), how deep it enters it, and how far its wrist is from the nearest
  ground-truth wrist (and that grasp's rotation). The contact maps were made by those grasps, so a model
  that reads them can put the hand back where it was.

Both return plain dicts (JSON-able) and are what ``results/models/<task>/checks.json`` holds.
"""

from __future__ import annotations

import functools
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from tohgs.data.maps import MapDataset
from tohgs.geometry.neighbours import nearest_neighbours
from tohgs.hand.model import HandModel
from tohgs.hand.rotations import axis_angle_to_matrix, rotation_angle
from tohgs.data.batch import Batch
from tohgs.models.checkpoint import load_component
from tohgs.models.diffusion import sample
from tohgs.models.grasp_diffuser import GraspCondition

log = logging.getLogger(__name__)


def _derangement(n: int, generator: torch.Generator) -> torch.Tensor:
    """A permutation of range(n) without fixed points (n >= 2): a random shift of a random order."""
    order = torch.randperm(n, generator=generator)
    shift = int(torch.randint(1, n, (1,), generator=generator))
    perm = torch.empty(n, dtype=torch.long)
    perm[order] = order.roll(shift)
    return perm


@torch.no_grad()
def shuffled_condition_gap(model, data: MapDataset, n_samples: int = 256, seed: int = 0,
                           timesteps: tuple[int, ...] = (50, 200, 500, 800), hand: HandModel | None = None) -> dict:
    """Denoising loss with the true and with shuffled conditions, per timestep and overall.

    Args:
        model: the trained network (eval mode): a GraspDiffuser (loss: L_diff, the summed squared error of
            the normalised grasp) or a ContactDiffuser (the mean squared error of its target, the noise or
            the clean map).
        data: training items (``per="grasp"``).
        n_samples: items drawn (with replacement, seeded).
        timesteps: the t at which both losses are measured (the same noise for both).
        hand: the hand model; needed by a GraspDiffuser that reads maps signed by the thumb
            (``thumb_sign``), whose maps it signs as training does.

    Returns:
        ``{"true": {t: loss}, "shuffled": {t: loss}, "gap": (shuffled - true) / true over all t}``; the
        shuffle pairs samples of different configurations where the data has more than one. For
        GraspDiffuser also ``"context"`` / ``"gap_context"``: the sample's own frame (the contact frame is
        derived from the map, so it is part of the condition too) with only the network's context swapped.
    """
    g = torch.Generator().manual_seed(seed)
    idx = torch.randint(0, len(data), (n_samples,), generator=g).tolist()
    batch = Batch.collate([data[i] for i in idx])
    configs = torch.as_tensor([data.index[i][0] * 1_000_000 + int(data.shards[data.index[i][0]].grasp_config[data.index[i][1]])
                               for i in idx])
    perm = _derangement(n_samples, g)
    for _ in range(20):  # prefer partners of another configuration
        same = configs[perm] == configs
        if not same.any() or len(set(configs.tolist())) < 2:
            break
        perm[same] = perm[same][torch.randperm(int(same.sum()), generator=g)]
        perm = torch.where(perm == torch.arange(n_samples), perm.roll(1), perm)
    sched = model.schedule
    grasps = model.role == "grasp"
    if grasps and getattr(model, "reads_signed_contact", False):  # the maps as it was trained on them
        if hand is None:
            raise ValueError("a GraspDiffuser reading maps signed by the thumb (thumb_sign) is checked with the hand model")
        batch = batch.with_contact(model.maps_read(batch.contact, batch.points, batch.grasp, hand))
    shuffled = batch.index(perm)
    if grasps:
        own = model.condition(batch.points, batch.normals, batch.contact)
        other = model.condition(shuffled.points, shuffled.normals, shuffled.contact)
        # Each sample's own grasp under a condition: the training loss of a batch whose conditions were
        # shuffled. "context" keeps the sample's own frame and swaps only what the network reads.
        context = GraspCondition(other.glob, other.tokens, own.rotation, own.origin, own.points)
        cases = {"true": (own, model.encode(batch.grasp, own)),
                 "shuffled": (other, model.encode(batch.grasp, other)),
                 "context": (context, model.encode(batch.grasp, own))}
    else:
        x0 = 2 * batch.contact - 1
        cases = {"true": (model.batch_condition(batch), x0), "shuffled": (model.batch_condition(shuffled), x0)}
    out: dict = {k: {} for k in cases}
    for t in timesteps:
        tt = torch.full((n_samples,), t, dtype=torch.long)
        noise = torch.randn(cases["true"][1].shape, generator=g)
        for key, (cond, x0) in cases.items():
            x_t = sched.q_sample(x0, noise, tt)
            pred = model(x_t, tt, cond)
            if grasps:
                loss = ((pred - x0) ** 2).sum(-1).mean()
            else:  # the network's own target: the noise (epsilon) or the clean map (sample)
                loss = ((pred - (noise if sched.cfg.prediction == "epsilon" else x0)) ** 2).mean()
            out[key][str(t)] = float(loss)
    true = sum(out["true"].values())
    for key in [k for k in cases if k != "true"]:
        out[f"gap_{key}" if key != "shuffled" else "gap"] = (sum(out[key].values()) - true) / max(true, 1e-12)
    return out


@torch.no_grad()
def grasp_fit(model, hand: HandModel, data: MapDataset, max_configs: int = 24, samples: int = 4, steps: int = 20,
              sampler: str = "ddim", touch: float = 0.005, seed: int = 0) -> dict:
    """Grasps sampled from the ground-truth contact maps of training configurations, against the
    configuration's ground-truth grasps, and the same for the trivial baseline.

    The baseline is the normaliser's mean put through the model's frame (``decode(0)``): the average
    training grasp in the network frame, or, with ``frame="contact"``, at its average place relative to
    each map's contact frame. A network that ignores what it reads does no better than that.

    Args:
        model: a trained GraspDiffuser (eval mode).
        hand: the hand model.
        data: training items (``per="grasp"``; augmentation off, so grasps and points share the frame).
        max_configs: configurations looked at (the first ones with a grasp, in shard order).
        samples: grasps per configuration, one per ground-truth contact map (cycled).
        touch: a hand touches the object when some vertex is within this distance of the cloud, m.

    Returns:
        For the model and for ``baseline``: ``touch_rate`` (fraction of hands that touch),
        ``wrist_error_median`` (m, to the nearest ground-truth wrist of the configuration) and
        ``rotation_error_median`` (degrees, to that grasp).
    """
    g = torch.Generator().manual_seed(seed)
    by_config: dict[tuple[int, int], list[int]] = {}
    for i, (s, r) in enumerate(data.index):
        by_config.setdefault((s, int(data.shards[s].grasp_config[r])), []).append(i)
    keys = list(by_config)[:max_configs]
    wrist0 = hand.rest_joints[0]
    stats = {k: {"touch": [], "wrist": [], "rotation": []} for k in ("model", "baseline")}
    for s, c in keys:
        items = [data[i] for i in by_config[(s, c)]]
        true = torch.as_tensor(np.stack([it["grasp"] for it in items]))
        pick = [k % len(items) for k in range(samples)]
        pts = torch.as_tensor(items[0]["points"])[None].expand(samples, -1, -1)
        nrm = torch.as_tensor(items[0]["normals"])[None].expand(samples, -1, -1)
        cmap = torch.as_tensor(np.stack([items[k]["contact"] for k in pick]))
        if getattr(model, "reads_signed_contact", False):  # each map signed by its grasp's thumb
            cmap = model.maps_read(cmap, pts, true[pick], hand)
        cond = model.condition(pts, nrm, cmap)
        x0 = sample(lambda xt, tt: model(xt, tt, cond), (samples, model.dim), model.diffusion, sampler, steps, g)
        for key, pred in (("model", model.decode(x0, cond)), ("baseline", model.decode(torch.zeros_like(x0), cond))):
            d = torch.cdist(pts, hand(pred).vertices).min(-1).values  # (S, N) object point to hand
            stats[key]["touch"] += (d.min(-1).values < touch).tolist()
            dist = torch.cdist(pred[:, :3] + wrist0, true[:, :3] + wrist0)  # (S, G) wrist to wrist
            best = dist.argmin(-1)
            stats[key]["wrist"] += dist.min(-1).values.tolist()
            stats[key]["rotation"] += torch.rad2deg(rotation_angle(axis_angle_to_matrix(pred[:, 3:6]),
                                                                    axis_angle_to_matrix(true[best, 3:6]))).tolist()

    def summary(v: dict[str, list]) -> dict:
        if not v["wrist"]:
            return {"touch_rate": math.nan, "wrist_error_median": math.nan, "rotation_error_median": math.nan}
        return {"touch_rate": float(np.mean(v["touch"])), "wrist_error_median": float(np.median(v["wrist"])),
                "rotation_error_median": float(np.median(v["rotation"]))}

    return {"configs": len(keys), "grasps": len(stats["model"]["wrist"]), **summary(stats["model"]),
            "baseline": summary(stats["baseline"])}


@torch.no_grad()
def permuted_map_gap(model, data: MapDataset, n_samples: int = 256, seed: int = 0,
                     timesteps: tuple[int, ...] = (50, 200, 500, 800)) -> dict:
    """ContactDiffuser's denoising loss (the mean squared error of its target) on (B, N) true maps and on the
    same maps with each map's values permuted across its N points (module docstring), per timestep.

    Returns:
        ``{"true": {t: loss}, "permuted": {t: loss}, "gap": (permuted - true) / true over all t}``.
    """
    g = torch.Generator().manual_seed(seed)
    idx = torch.randint(0, len(data), (n_samples,), generator=g).tolist()
    batch = Batch.collate([data[i] for i in idx])
    x0 = 2 * batch.contact - 1  # (B, N)
    perm = torch.argsort(torch.rand(x0.shape, generator=g), dim=-1)
    cases = {"true": x0, "permuted": torch.gather(x0, 1, perm)}
    cond = model.batch_condition(batch)
    sched = model.schedule
    out: dict = {k: {} for k in cases}
    for t in timesteps:
        tt = torch.full((n_samples,), t, dtype=torch.long)
        noise = torch.randn(x0.shape, generator=g)
        for key, target in cases.items():
            pred = model(sched.q_sample(target, noise, tt), tt, cond)
            want = noise if sched.cfg.prediction == "epsilon" else target
            out[key][str(t)] = float(((pred - want) ** 2).mean())
    true = sum(out["true"].values())
    out["gap"] = (sum(out["permuted"].values()) - true) / max(true, 1e-12)
    return out


def _iou(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """IoU of boolean maps: (S, N) against (G, N) -> (S, G)."""
    a, b = a.float(), b.float()
    inter = a @ b.T
    union = a.sum(-1, keepdim=True) + b.sum(-1) - inter
    return torch.where(union > 0, inter / union.clamp_min(1), torch.ones_like(inter))


def _configurations(data: MapDataset, max_configs: int) -> tuple[dict[tuple[int, int], list[int]], list[tuple[int, int]]]:
    """The items of ``data`` by (shard, configuration), and the first ``max_configs`` of those keys."""
    by_config: dict[tuple[int, int], list[int]] = {}
    for i, (s, r) in enumerate(data.index):
        by_config.setdefault((s, int(data.shards[s].grasp_config[r])), []).append(i)
    return by_config, list(by_config)[:max_configs]


def _prior_index(data: MapDataset, item: int) -> int:
    """The index in its object's prior store of the grasp of ``data``'s item ``item`` (per-grasp items)."""
    s, r = data.index[item]
    return int(data.shards[s].grasp_prior_index[r])


def _other_config_ious(data: MapDataset, by_config: dict, key: tuple[int, int], true: torch.Tensor,
                       threshold: float) -> tuple[list[float], list[float]]:
    """The best IoU with the (G, N) boolean ``true`` maps of configuration ``key`` of each true map of the
    other configurations of its object (a predictor that draws one of the object's grasps without looking
    at the scene): all of them, and those of the grasps ``key`` does not hold itself.

    A prior grasp kept by two configurations gives both the same map (the maps lie on the object's points),
    so the first list scores those copies of ``key``'s own maps 1; the second leaves them out and so
    compares like with like: a map that is not one of the configuration's, as a sampled map is not."""
    s, c = key
    obj = int(data.shards[s].object_id[c])
    own = {_prior_index(data, i) for i in by_config[key]}
    others = [i for (s2, c2), ids in by_config.items() if (s2, c2) != (s, c)
              and int(data.shards[s2].object_id[c2]) == obj and data.shards[s2].attrs["objects"] == data.shards[s].attrs["objects"]
              for i in ids]
    if not others:
        return [], []
    other = torch.as_tensor(np.stack([data[i]["contact"] for i in others])) > threshold
    best = _iou(other, true).max(-1).values.tolist()
    return best, [b for b, i in zip(best, others) if _prior_index(data, i) not in own]


def _held_out_ious(true: torch.Tensor) -> list[float]:
    """Each of a configuration's (G, N) boolean true maps scored like a sampled map against the others
    (leave one out): what a sampler that draws new grasps from the configuration's own distribution scores,
    up to having G - 1 maps to match instead of G. Empty when G is 1."""
    if true.shape[0] < 2:
        return []
    iou = _iou(true, true)
    iou.fill_diagonal_(-1.0)
    return iou.max(-1).values.tolist()


def _reference_ious(data: MapDataset, by_config: dict, key: tuple[int, int], true: torch.Tensor, threshold: float,
                    into: dict[str, list[float]]) -> None:
    """Appends to ``into`` the IoUs the sampled maps of configuration ``key`` (its (G, N) boolean ``true``
    maps) are compared with: ``other`` and ``distinct`` (:func:`_other_config_ious`) and ``held``
    (:func:`_held_out_ious`)."""
    every, new = _other_config_ious(data, by_config, key, true, threshold)
    for name, values in (("other", every), ("distinct", new), ("held", _held_out_ious(true))):
        into.setdefault(name, []).extend(values)


def _reference_summary(into: dict[str, list[float]]) -> dict:
    """The checks' entries for the comparisons :func:`_reference_ious` gathered (:func:`contact_fit`)."""
    med = lambda v: float(np.median(v)) if v else math.nan  # noqa: E731
    distinct = into.get("distinct", [])
    return {"other_config_iou_median": med(into.get("other", [])), "other_config_distinct_iou_median": med(distinct),
            "other_config_distinct_maps": len(distinct), "held_out_iou_median": med(into.get("held", []))}


def _quantile(parts: list[torch.Tensor], q: float) -> float:
    """The ``q`` quantile of the values of the 1-D tensors ``parts`` together (NaN when there are none)."""
    return float(torch.quantile(torch.cat(parts).float(), q)) if parts else math.nan


def map_roughness(maps: torch.Tensor, points: torch.Tensor, k: int = 8) -> torch.Tensor:
    """(S,) roughness of (S, N) maps on one object's (N, 3) points: the mean over the points of the absolute
    difference between a point's value and the mean of its ``k`` nearest points' values. A map of coherent
    regions changes only at their borders; salt and pepper changes everywhere."""
    nb = nearest_neighbours(points[None], k)[0]  # (N, k)
    return (maps - maps[:, nb].mean(-1)).abs().mean(-1)


@torch.no_grad()
def contact_fit(model, data: MapDataset, max_configs: int = 24, samples: int = 4, steps: int = 20,
                sampler: str = "ddim", threshold: float = 0.5, seed: int = 0) -> dict:
    """Contact maps sampled for configurations of ``data`` against the configuration's ground-truth maps.

    A point is in contact where the map exceeds ``threshold`` (0.5: within about 1.1 cm of the hand at the
    contact alpha of 100). Each sampled map scores its best IoU with a ground-truth map of its own
    configuration. The comparison does the same for the ground-truth maps of the *other* configurations
    of the same object (the points are the same samples of the same mesh), each scored like a sampled map:
    a predictor that draws one of the object's grasps without looking at the scene. The same prior grasp
    kept in two configurations gives the same map, so some of these are copies of the configuration's own
    maps and score 1; the distinct comparison leaves those out (a sampled map is never a copy). The
    held-out comparison scores each true map of the configuration against its other true maps: what a
    sampler of the configuration's own grasp distribution would score.

    Returns:
        ``iou_median`` (sampled maps), ``other_config_iou_median`` (other configurations' maps, where the
        object has another configuration), ``other_config_distinct_iou_median`` (those of them whose grasp
        the configuration does not hold; ``other_config_distinct_maps`` of them), ``held_out_iou_median``
        (each true map against the configuration's others), ``contact_fraction`` (the sampled maps' mean share of
        points in contact; the ground truth's as ``true_contact_fraction``) and ``roughness`` (the sampled
        maps' mean :func:`map_roughness`; the ground truth's as ``true_roughness``).
    """
    g = torch.Generator().manual_seed(seed)
    by_config, keys = _configurations(data, max_configs)
    ious, frac, true_frac, rough, true_rough = [], [], [], [], []
    reference: dict[str, list[float]] = {}
    for key in keys:
        items = [data[i] for i in by_config[key]]
        true_values = torch.as_tensor(np.stack([it["contact"] for it in items]))
        true = true_values > threshold
        _reference_ious(data, by_config, key, true, threshold, reference)
        it = items[0]
        pts = torch.as_tensor(it["points"])[None].expand(samples, -1, -1)
        nrm = torch.as_tensor(it["normals"])[None].expand(samples, -1, -1)
        d_i = torch.as_tensor(it["d_init"])[None].expand(samples, -1)
        d_g = torch.as_tensor(it["d_goal"])[None].expand(samples, -1)
        cond = model.condition(pts, nrm, d_i, d_g)
        x = sample(lambda xt, tt: model(xt, tt, cond), (samples, pts.shape[1]), model.diffusion, sampler, steps, g)
        values = (x.clamp(-1, 1) + 1) / 2
        pred = values > threshold
        ious += _iou(pred, true).max(-1).values.tolist()
        frac.append(float(pred.float().mean()))
        true_frac.append(float(true.float().mean()))
        both = map_roughness(torch.cat([values, true_values.to(values)]), torch.as_tensor(it["points"]))
        rough += both[:samples].tolist()
        true_rough += both[samples:].tolist()
    mean = lambda v: float(np.mean(v)) if v else math.nan  # noqa: E731
    med = lambda v: float(np.median(v)) if v else math.nan  # noqa: E731
    return {"configs": len(keys), "iou_median": med(ious), **_reference_summary(reference),
            "contact_fraction": mean(frac), "true_contact_fraction": mean(true_frac),
            "roughness": mean(rough), "true_roughness": mean(true_rough)}


@torch.no_grad()
def representation_fit(model, hand: HandModel, data: MapDataset, curve: list[dict] | None = None,
                       max_configs: int = 24, samples: int = 4, threshold: float = 0.5, seed: int = 0) -> dict:
    """A ContactGen (``contact_gen`` kind) model's sampled representations for configurations of ``data``
    against the true ones of the configuration's grasps (module docstring).

    Returns:
        ``iou_median`` / ``other_config_iou_median`` / ``other_config_distinct_iou_median`` /
        ``other_config_distinct_maps`` / ``held_out_iou_median`` / ``contact_fraction`` /
        ``true_contact_fraction`` as :func:`contact_fit`; ``sample_iou_median``, the median IoU between two samples of one configuration
        (1: the samples are one map); ``reconstruction_iou_median``, the median IoU of each true map with the
        contact stage's posterior-mean reconstruction of it (what the stage can carry: low where it
        under-fits, whatever its prior), and ``contact_p99`` / ``true_contact_p99``, the 99th percentile of the
        sampled and the true contact values (a stage that hedges never nears 1); with parts, ``part_tv``, the
        total variation distance between the part labels' histograms over the sampled and the true contact
        points (0: the same use of the hand's parts; NaN when the samples have no point in contact), and
        ``part_agreement``, the share of points in contact in both a sample and its best true map that carry
        the same part; ``kl_<stage>``, each stage's KL at the last step of ``curve`` (the
        checkpoint's loss curve).
    """
    from tohgs.geometry.contact_parts import N_PARTS, part_contact

    g = torch.Generator().manual_seed(seed)
    by_config, keys = _configurations(data, max_configs)
    alpha = data.shards[0].alpha_contact
    ious, frac, true_frac, alike, agree, recon = [], [], [], [], [], []
    reference: dict[str, list[float]] = {}
    values, true_values = [], []
    hist_s, hist_t = torch.zeros(N_PARTS), torch.zeros(N_PARTS)
    for key in keys:
        items = [data[i] for i in by_config[key]]
        truth = Batch.collate(items)
        true = truth.contact > threshold  # (G, N)
        _reference_ious(data, by_config, key, true, threshold, reference)
        rep = model.sample_representation(Batch.collate([items[0]] * samples), g)
        pred = rep.contact > threshold  # (S, N)
        iou = _iou(pred, true)  # (S, G)
        ious += iou.max(-1).values.tolist()
        pair = _iou(pred, pred)
        alike += pair[~torch.eye(samples, dtype=torch.bool)].tolist()
        recon += _iou(model.reconstruct_contact(truth) > threshold, true).diagonal().tolist()  # each map's own
        values.append(rep.contact.flatten())
        true_values.append(truth.contact.flatten())
        frac.append(float(pred.float().mean()))
        true_frac.append(float(true.float().mean()))
        if rep.part is not None:
            out = hand(truth.grasp)
            true_part = part_contact(truth.points, out.vertices, out.joints, out.rotations, hand.part_labels, alpha).part
            hist_s += torch.bincount(rep.part[pred], minlength=N_PARTS).float()
            hist_t += torch.bincount(true_part[true], minlength=N_PARTS).float()
            best = iou.argmax(-1)  # each sample's best true map
            both = pred & true[best]
            if both.any():
                agree.append(float((rep.part == true_part[best])[both].float().mean()))
    med = lambda v: float(np.median(v)) if v else math.nan  # noqa: E731
    result = {"configs": len(keys), "iou_median": med(ious), **_reference_summary(reference),
              "sample_iou_median": med(alike), "reconstruction_iou_median": med(recon),
              "contact_p99": _quantile(values, 0.99), "true_contact_p99": _quantile(true_values, 0.99),
              "contact_fraction": float(np.mean(frac)) if frac else math.nan,
              "true_contact_fraction": float(np.mean(true_frac)) if true_frac else math.nan}
    if model.cfg.parts:
        ps, pt = hist_s / hist_s.sum().clamp_min(1), hist_t / hist_t.sum().clamp_min(1)
        tv = float(0.5 * (ps - pt).abs().sum()) if hist_s.sum() > 0 and hist_t.sum() > 0 else math.nan
        result.update(part_tv=tv, part_agreement=med(agree))
    last = (curve or [{}])[-1]
    result.update({k: float(last[k]) for k in ("kl_contact", "kl_part", "kl_direction") if k in last})
    return result


@dataclass
class _Subject:
    """What a check measures: a trained component on its task's training shards."""

    model: object
    meta: dict
    hand: HandModel
    plain: MapDataset  # the training shards, one item per grasp, unturned
    shard_paths: list
    seed: int

    @functools.cached_property
    def seen(self) -> MapDataset:
        """The training shards as the model was trained on them: its own augmentation."""
        cfg = self.meta["training_config"]
        return MapDataset(self.shard_paths, per="grasp", rotation=cfg["rotation"], seed=self.seed,
                          rotation_max=cfg.get("rotation_max", np.pi / 6))


#: The checks a component kind may declare (its schema block's ``x-checks``), by name: the key of its result
#: in ``checks.json`` and the measurement.
CHECKS: dict[str, tuple[str, Callable[[_Subject], dict]]] = {
    "shuffled_condition": ("shuffled_condition", lambda s: shuffled_condition_gap(s.model, s.seen, seed=s.seed,
                                                                                  hand=s.hand)),
    "permuted_map": ("permuted_map", lambda s: permuted_map_gap(s.model, s.seen, seed=s.seed)),
    "contact_fit": ("fit", lambda s: contact_fit(s.model, s.plain, seed=s.seed)),
    "grasp_fit": ("fit", lambda s: grasp_fit(s.model, s.hand, s.plain, seed=s.seed)),
    "representation_fit": ("fit", lambda s: representation_fit(s.model, s.hand, s.plain, s.meta.get("loss_curve"),
                                                               seed=s.seed)),
}


def model_checks(task: str, shard_paths: list[str | Path], checkpoints: dict[str, str | Path], hand: HandModel,
                 out: str | Path, checks: dict[str, list[str]], seed: int = 0) -> dict:
    """The checks of each of a task's trained components (``checkpoints``: by component name) on their
    training shards; ``checks``: the names (of :data:`CHECKS`) each component's kind declares (its schema
    block's ``x-checks``; none: the entry says so). Written as JSON, one entry per component.

    Raises:
        ValueError: a check name :data:`CHECKS` does not know.
    """
    from tohgs.io import write_json

    unknown = sorted({c for names in checks.values() for c in names} - set(CHECKS))
    if unknown:
        raise ValueError(f"unknown model checks {unknown} (known: {', '.join(CHECKS)})")
    torch.set_num_threads(1)
    result: dict = {"task": task}
    plain = MapDataset(shard_paths, per="grasp", rotation="none")
    for name, ckpt in checkpoints.items():
        model, meta = load_component(ckpt, task=task, component=name)
        if not checks.get(name):
            result[name] = {"kind": model.kind, "checks": "none for this kind"}
            continue
        subject = _Subject(model, meta, hand, plain, list(shard_paths), seed)
        result[name] = {"kind": model.kind}
        for check in checks[name]:
            key, measure = CHECKS[check]
            result[name][key] = measure(subject)
        log.info("%s/%s: %s", task, name, result[name])
    write_json(out, result)
    return result
