"""Benchmark of the ContactDiffuser on the CPU at the default's sizes: seconds per training step (the loss on
one batch of ``components.contact_diffuser.training.batch`` samples of all ``maps.points.n_points`` points,
backward, AdamW) and per sampling step (one test configuration's 16 samples, DDIM as ``prediction.sampler``),
with one torch thread as the workflow's jobs.

``--base COMMIT`` builds that commit's ContactDiffuser (:mod:`base_commit`) with the same weights and times it
beside the working tree's, interleaved step by step on the same batches, so the ratio of their medians does
not depend on the machine's load; it also records whether the two give the same loss and the same sampled
maps bit for bit, and the largest difference of their gradients. The batches are synthetic (bench_train's
sphere clouds and random maps): a step's cost depends on the sizes, not the values. Writes
``benchmarks/results/contact_diffuser.json`` (or ``--out``) with the machine, the CPU and the commit.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np
import torch

from tohgs.config import validate_config
from tohgs.data.batch import Batch
from tohgs.io import write_json
from tohgs.models.component import build_component

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "benchmarks"))
from base_commit import base_module, commit_label, cpu_name, short_commit  # noqa: E402
from bench_train import synthetic_items  # noqa: E402


def _train_step(model: torch.nn.Module, opt: torch.optim.Optimizer, batch: Batch, seed: int) -> tuple[float, float, list]:
    """Seconds of one training step, its loss and the gradients it applied (kept on the parameters until the
    model's next step, so they are read after the clock stops)."""
    t0 = time.perf_counter()
    loss = model.loss(batch, torch.Generator().manual_seed(seed))["loss"]
    opt.zero_grad(set_to_none=True)
    loss.backward()
    opt.step()
    seconds = time.perf_counter() - t0
    return seconds, float(loss.detach()), [p.grad for p in model.parameters() if p.grad is not None]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--steps", type=int, default=10, help="timed training steps (after one warm-up step)")
    ap.add_argument("--sampling-steps", type=int, default=20, help="sampler steps of the timed sampling runs")
    ap.add_argument("--base", default=None, help="a commit whose ContactDiffuser is timed beside the working tree's")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "contact_diffuser.json"))
    args = ap.parse_args()
    torch.set_num_threads(1)
    torch.backends.mha.set_fastpath_enabled(False)  # as tohgs.methods.predict
    cfg = validate_config({})
    block, points = cfg["components"]["contact_diffuser"], cfg["maps"]["points"]
    settings = {**cfg["training"], **block["training"]}
    n = settings["train_points"] or points["n_points"]
    rng = np.random.default_rng(0)
    items = synthetic_items(32, n, points["n_scene_points"], rng)
    builders = {"new": build_component}
    if args.base:
        builders["base"] = base_module("tohgs.models.component", args.base).build_component
    models, opts = {}, {}
    for name, build in builders.items():
        torch.manual_seed(0)
        models[name] = build(block["kind"], block["network"])
        if name != "new":
            models[name].load_state_dict(models["new"].state_dict())
        opts[name] = torch.optim.AdamW(models[name].parameters(), lr=settings["lr"])
    times: dict[str, list[float]] = {k: [] for k in models}
    same_loss, grad_diff = [], 0.0
    for step in range(args.steps + 1):  # the first step warms up
        batch = Batch.collate([items[int(i)] for i in rng.integers(0, len(items), settings["batch"])])
        results = {k: _train_step(models[k].train(), opts[k], batch, step) for k in models}
        if step:
            for k, (sec, _, _) in results.items():
                times[k].append(sec)
        if "base" in results:
            same_loss.append(results["new"][1] == results["base"][1])
            grad_diff = max(grad_diff, max(float((a - b).abs().max()) for a, b in zip(results["new"][2], results["base"][2])))
            models["base"].load_state_dict(models["new"].state_dict())  # the next step starts from equal weights
    test = Batch.collate(synthetic_items(1, points["n_points"], points["n_scene_points"], rng)).repeat(cfg["prediction"]["samples"])
    sampled, sampling = {}, {k: [] for k in models}
    for repeat in range(3):
        for k, model in models.items():
            t0 = time.perf_counter()
            sampled[k] = model.eval().sample_contact(test, "ddim", args.sampling_steps, torch.Generator().manual_seed(repeat))
            sampling[k].append((time.perf_counter() - t0) / args.sampling_steps)
    rows = {}
    for k in models:
        rows[k] = {"train_seconds_per_step": round(float(np.median(times[k])), 4),
                   "sampling_seconds_per_step": round(float(np.median(sampling[k])), 4)}
    out = {"benchmark": "contact_diffuser", "machine": platform.processor() or platform.machine(), "cpu": cpu_name(),
           "threads": 1, "commit": commit_label(), **({"base_commit": short_commit(args.base)} if args.base else {}),
           "batch": settings["batch"], "train_points": n, "samples_per_config": cfg["prediction"]["samples"],
           "timed_steps": args.steps, "unit": "seconds", "new": rows["new"]}
    if "base" in rows:
        out["base"] = rows["base"]
        out["train_ratio_to_base"] = round(rows["new"]["train_seconds_per_step"] / rows["base"]["train_seconds_per_step"], 3)
        out["sampling_ratio_to_base"] = round(rows["new"]["sampling_seconds_per_step"] / rows["base"]["sampling_seconds_per_step"], 3)
        out["same_loss_every_step"] = bool(all(same_loss))
        out["largest_gradient_difference"] = grad_diff
        out["same_sampled_maps"] = bool(torch.equal(sampled["new"], sampled["base"]))
    print(out, flush=True)
    write_json(args.out, out)


if __name__ == "__main__":
    main()
