"""Benchmark of training at the paper's sizes on the CPU: seconds per training step of every component of
``config/paper.yaml`` (its network, batch and ``training.train_points``), and seconds per DDIM step of the
two diffusers' samplers on one test configuration (16 samples of the paper's 2048 points).

A training step is what :func:`tohgs.models.train.train_component` does per step: the component's loss
on one batch, backward, gradient clipping, AdamW and the EMA. The batches are synthetic (random clouds,
maps and grasps near the origin): the cost of a step does not depend on the values, only on the sizes.
``prepare`` gets a small stand-in of the training data (it sets normalisers and the hand). One torch
thread, as the workflow's jobs (``training.threads``, ``prediction.threads``). Writes
``benchmarks/results/train_cpu.json``; docs/scale.md turns it into the paper scale's training cost.

It is slow at these sizes: about 11 minutes on one core of the 2-core reference machine (a SceneDiffuser
step alone takes over a minute, a ContactDiffuser DDIM step on 16 x 2048 points 28 s); ``--components``
times a subset.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import torch
import yaml

from tohgs.config import validate_config
from tohgs.data.batch import Batch
from tohgs.hand import load_hand
from tohgs.models.component import build_component
from tohgs.models.train import EMA

REPO = Path(__file__).resolve().parent.parent


class _Data:
    """The part of a :class:`tohgs.data.maps.MapDataset` that ``prepare`` reads."""

    rotation = "none"

    def __init__(self, items: list[dict]):
        self.items = items
        grasps = np.stack([it["grasp"] for it in items])
        self.shards = [SimpleNamespace(attrs={"alpha_contact": 100.0}, alpha_contact=100.0, grasp=grasps,
                                       n_grasps=len(grasps))]

    def __len__(self) -> int:
        return len(self.items)

    def item(self, i: int, draw: int) -> dict:
        return self.items[i]


def synthetic_items(n: int, points: int, scene_points: int, rng: np.random.Generator) -> list[dict]:
    """``n`` synthetic samples: an object cloud on a 4 cm sphere, a scene cloud, maps and a grasp."""
    out = []
    for _ in range(n):
        p = rng.normal(size=(points, 3))
        p /= np.linalg.norm(p, axis=1, keepdims=True)
        s = rng.uniform(-0.3, 0.3, size=(scene_points, 3))
        grasp = np.zeros(51)
        grasp[:3] = rng.normal(0, 0.02, 3) + [0.0, 0.08, 0.0]
        grasp[3:] = rng.normal(0, 0.2, 48)
        out.append({"points": 0.04 * p, "normals": p, "d_init": rng.uniform(0, 1, points), "d_goal": rng.uniform(0, 1, points),
                    "scene": s, "scene_normals": np.tile([0.0, 0.0, 1.0], (scene_points, 1)), "goal_transform": np.eye(4),
                    "contact": rng.uniform(0, 1, points), "grasp": grasp})
    return out


def _train_step_s(name: str, block: dict, training: dict, hand, items: list[dict], steps: int) -> dict:
    torch.manual_seed(0)
    model = build_component(block["kind"], block["network"])
    model.prepare(_Data(items), "placing", hand)
    settings = {**training, **block["training"]}
    opt = torch.optim.AdamW(model.parameters(), lr=settings["lr"], betas=settings["betas"],
                            weight_decay=settings["weight_decay"])
    ema = EMA(model.parameters(), decay=settings["ema_decay"])
    gen = torch.Generator().manual_seed(0)
    rng = np.random.default_rng(0)
    model.train()
    times = []
    for k in range(steps + 1):  # the first step warms up
        batch = Batch.collate([items[int(i)] for i in rng.integers(0, len(items), settings["batch"])])
        t0 = time.perf_counter()
        losses = model.loss(batch, gen)
        opt.zero_grad(set_to_none=True)
        losses["loss"].backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        opt.step()
        ema.step(model.parameters())
        if k:
            times.append(time.perf_counter() - t0)
    n_params = sum(p.numel() for p in model.parameters())
    row = {"kind": block["kind"], "parameters": n_params, "batch": settings["batch"], "steps": settings["steps"],
           "seconds_per_step": round(float(np.median(times)), 3), "timed_steps": steps}
    row["hours_per_training"] = round(row["seconds_per_step"] * settings["steps"] / 3600, 3)
    print(name, row, flush=True)
    return row, model


def _ddim_step_s(fn, steps: tuple[int, int] = (1, 3)) -> dict:
    """Seconds per sampler step and the fixed cost (the conditioning), from runs of two step counts."""
    t = []
    for k in steps:
        t0 = time.perf_counter()
        with torch.no_grad():
            fn(k)
        t.append(time.perf_counter() - t0)
    per = (t[1] - t[0]) / (steps[1] - steps[0])
    return {"seconds_per_step": round(per, 4), "seconds_fixed": round(max(t[0] - per * steps[0], 0.0), 4)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--config", default=str(REPO / "config" / "paper.yaml"))
    ap.add_argument("--steps", type=int, default=2, help="timed steps per component (after one warm-up step)")
    ap.add_argument("--components", nargs="*", default=None, help="default: every component of the config")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "train_cpu.json"))
    args = ap.parse_args()
    torch.set_num_threads(1)
    torch.backends.mha.set_fastpath_enabled(False)  # as tohgs.methods.predict
    cfg = validate_config(yaml.safe_load(Path(args.config).read_text()) or {}, base_dir=REPO)
    training, maps = cfg["training"], cfg["maps"]["points"]
    hand = load_hand(cfg["hand"]["model"])
    rng = np.random.default_rng(0)
    train_items = synthetic_items(32, training["train_points"] or maps["n_points"], maps["n_scene_points"], rng)
    out = {"benchmark": "training steps at the paper's sizes", "config": Path(args.config).name, "device": "cpu",
           "machine": platform.processor() or platform.machine(), "torch": torch.__version__, "threads": 1,
           "train_points": training["train_points"], "n_points": maps["n_points"],
           "n_scene_points": maps["n_scene_points"], "unit": "seconds", "components": {}}
    models = {}
    for name in args.components or list(cfg["components"]):
        out["components"][name], models[name] = _train_step_s(name, cfg["components"][name], training, hand,
                                                             train_items, args.steps)
    # sampling: one test configuration, 16 samples of the paper's points, DDIM (prediction.sampler)
    s = cfg["prediction"]["samples"]
    test = Batch.collate(synthetic_items(1, maps["n_points"], maps["n_scene_points"], rng)).repeat(s)
    gen = torch.Generator().manual_seed(0)
    sampling = {}
    if "contact_diffuser" in models:
        cd = models["contact_diffuser"].eval()
        sampling["contact_diffuser"] = _ddim_step_s(lambda k: cd.sample_contact(test, "ddim", k, gen))
    if "grasp_diffuser" in models:
        gd = models["grasp_diffuser"].eval()
        sampling["grasp_diffuser"] = _ddim_step_s(lambda k: gd.sample_grasps(test, "ddim", k, gen))
    for row in sampling.values():
        row["seconds_per_configuration"] = round(row["seconds_fixed"] + row["seconds_per_step"] * cfg["prediction"]["steps"], 2)
    out["sampling"] = {"samples_per_config": s, "points": maps["n_points"], "ddim_steps": cfg["prediction"]["steps"],
                       **sampling}
    print("sampling", out["sampling"], flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
