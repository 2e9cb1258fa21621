"""One prediction job for any method: S grasps per test configuration, placed at the target's initial
pose and carried to its goal pose by ``T_goal T_init^-1`` (paper section 4.4).

The method (:mod:`tohgs.methods`) returns grasps in the network frame; this module alone turns them into
the world frame (``+ centroid``) and carries them to the goal pose, and writes the prediction store
(:mod:`tohgs.data.predictions`).
"""

from __future__ import annotations

import importlib
import logging
import zlib
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import torch

from tohgs.data.batch import Batch
from tohgs.data.maps import MapDataset
from tohgs.data.predictions import read_predictions, write_predictions
from tohgs.geometry.grasp import transform_grasp
from tohgs.hand.layout import GRASP_DIM
from tohgs.methods import method_kind_exists, method_kinds, method_module
from tohgs.methods.base import GeneratorSettings, Method, Request
from tohgs.models.checkpoint import load_component, pick_device
from tohgs.settings import settings_from

log = logging.getLogger(__name__)


def method_class(kind: str) -> type[Method]:
    """The class ``METHOD`` of ``tohgs.methods.<kind>``; ``ValueError`` for an unknown kind."""
    if not method_kind_exists(kind):
        raise ValueError(f"unknown method kind {kind!r} (known: {', '.join(method_kinds())})")
    return importlib.import_module(method_module(kind)).METHOD


def configuration_streams(seed: int, obj: str, config_index: int) -> tuple[torch.Generator, np.random.Generator]:
    """The torch and numpy random streams of one test configuration's predictions, seeded by the job's
    ``seed``, the object's name and the configuration's index in its scene store: a configuration's samples do
    not depend on which configurations the job predicts before it (``maps.test_configs``, the shards)."""
    key = [int(seed), zlib.crc32(obj.encode()), int(config_index)]
    torch_seed = int(np.random.SeedSequence(key).generate_state(1, np.uint64)[0] >> np.uint64(1))
    return torch.Generator().manual_seed(torch_seed), np.random.default_rng(key)


def predict(task: str, name: str, method: dict[str, Any], test_shards: list[str | Path],
            checkpoints: dict[str, str | Path], settings: dict[str, Any], out: str | Path,
            hand: str | Path | None = None, base: str | Path | None = None, complete: bool = False
            ) -> dict[str, np.ndarray]:
    """Predict S grasps per test configuration of ``task`` with the method ``name`` and write the store ``out``.

    Args:
        task, name: recorded in the store.
        method: the method's config block (``kind`` and its keys).
        test_shards: the task's test map shards.
        checkpoints: the trained components the method names, by config name.
        settings: a mapping of the kind's ``Settings`` (:attr:`tohgs.methods.base.Method.Settings`): a key the
            kind does not read is an error.
        hand: the hand file (``results/hand/hand.npz``), for the methods that pose hands.
        base: the prediction store of the method this one is of (kind ``filtered``: its key ``of``).
        complete: ``settings`` must hold every key the kind reads (the workflow's jobs: a missing key is an
            error, not the dataclass's default).

    Returns:
        The arrays written (:mod:`tohgs.data.predictions`).
    """
    kind = method_class(method["kind"])
    s = settings_from(kind.Settings, settings, complete=complete, where=f"method {name!r} (kind {method['kind']}): settings")
    torch.set_num_threads(max(1, s.threads))
    # PyTorch's inference "fast path" for transformer layers materialises ContactDiffuser's 512 x 512
    # attention; the regular path runs scaled_dot_product_attention and is 1.7x faster per layer on a CPU
    # (same outputs to 1e-6). A process-wide switch: predict runs as its own job.
    torch.backends.mha.set_fastpath_enabled(False)
    device = pick_device(s.device)
    models, meta = {}, {}
    for comp, path in checkpoints.items():
        models[comp], ckpt = load_component(path, device, task=task, component=comp)
        curve = ckpt.get("loss_curve") or []
        meta[comp] = {"kind": ckpt["kind"], "final_loss": curve[-1]["loss"] if curve else None}
    hand_model = None
    if hand is not None:
        from tohgs.hand import HandAssets, HandModel

        hand_model = HandModel(HandAssets.load(hand)).to(device)
    runner = kind(name, method, models, s, device, hand_model, None if base is None else read_predictions(base))
    data = MapDataset(test_shards, per="config")
    rows: dict[str, list] = {k: [] for k in ("object_id", "config_index", "contact", "grasp_init", "grasp_goal", "kept")}
    diagnostics: dict[str, list[float]] = {}
    seconds: dict[str, float] = {}
    skipped = 0
    from tqdm import tqdm

    def requests(start: int) -> list[Request]:
        out = []
        for i in range(start, min(start + s.chunk, len(data))):
            item = data[i]
            shard, c = data.shards[item["shard"]], item["row"]
            gen, rng = configuration_streams(s.seed, shard.attrs["objects"][int(item["object_id"])], int(item["config_index"]))
            out.append(Request(Batch.collate([item], device).repeat(s.samples), shard, c, gen, rng))
        return out

    with tqdm(total=len(data), desc=f"predict {task}/{name}", mininterval=5.0) as bar:
        for start in range(0, len(data), s.chunk):
            chunk = requests(start)
            preds = runner.predict_many(chunk)
            if len(preds) != len(chunk):
                raise RuntimeError(f"method {name!r} returned {len(preds)} predictions for {len(chunk)} configurations")
            for req, pred in zip(chunk, preds):
                if pred is None:
                    skipped += 1
                    continue
                shard, c = req.shard, req.row
                for k, v in pred.seconds.items():
                    seconds[k] = seconds.get(k, 0.0) + v
                world = np.asarray(pred.grasp, dtype=np.float64).copy()
                world[:, :3] += shard.centroid[c]
                rows["object_id"].append(int(shard.object_id[c]))
                rows["config_index"].append(int(shard.config_index[c]))
                rows["contact"].append(np.asarray(pred.contact, np.float32))
                rows["grasp_init"].append(world.astype(np.float32))
                rows["grasp_goal"].append(transform_grasp(world, shard.goal_transform[c],
                                                          np.asarray(shard.attrs["hand_wrist"])).astype(np.float32))
                rows["kept"].append(np.ones(s.samples, bool) if pred.kept is None else np.asarray(pred.kept, bool))
                for k in set(diagnostics) | set(pred.info):  # a key a configuration lacks is NaN there
                    diagnostics.setdefault(k, [float("nan")] * (len(rows["kept"]) - 1)).append(float(pred.info.get(k, np.nan)))
            bar.update(len(chunk))
    n = len(rows["object_id"])
    if n == 0:  # e.g. ground-truth maps for test configurations that kept no task grasp
        log.warning("%s/%s: no test configuration could be predicted (%d skipped)", task, name, skipped)
    n_points = data.shards[0].points.shape[1] if data.shards else 0
    empty = {"contact": (0, s.samples, n_points), "grasp_init": (0, s.samples, GRASP_DIM),
             "grasp_goal": (0, s.samples, GRASP_DIM), "kept": (0, s.samples)}
    arrays = {"object_id": np.asarray(rows["object_id"], np.int32), "config_index": np.asarray(rows["config_index"], np.int32),
              **{k: np.stack(rows[k]) if n else np.zeros(shape, np.float32) for k, shape in empty.items()}}
    per = max(1, sum(len(k) for k in rows["kept"]))
    timing = {f"seconds_per_{k}": v / per for k, v in seconds.items()}
    vocab = data.shards[0].attrs["objects"] if data.shards else []
    discarded = int((~arrays["kept"]).sum())
    write_predictions(arrays, {"task": task, "method": name, "method_config": method, "objects": vocab,
                               "components": meta, "config": asdict(s), "timing": timing, "skipped_configs": skipped,
                               "discarded": discarded,
                               "diagnostics": {k: [None if np.isnan(x) else x for x in v] for k, v in diagnostics.items()}},
                      out)
    sampler = f" ({s.sampler}, {s.steps} steps)" if isinstance(s, GeneratorSettings) else ""
    if hasattr(s, "grasp_sampler"):
        sampler += f" (grasps: {s.grasp_sampler}, {s.grasp_steps} steps)"
    log.info("%s/%s: %d configurations x %d grasps (%d skipped, %d grasps discarded); %s%s", task, name, n,
             s.samples, skipped, discarded, ", ".join(f"{k} {v:.3f} s" for k, v in timing.items()) or "no timing",
             sampler)
    for k, v in diagnostics.items():
        log.info("%s/%s: %s mean %.4g, median %.4g over %d configurations", task, name, k, np.nanmean(v),
                 np.nanmedian(v), len(v))
    return arrays
