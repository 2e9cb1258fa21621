"""Benchmark of test-time sampling: seconds per contact map (ContactDiffuser) and per grasp (GraspDiffuser)
with full DDPM (all T = 1000 steps) and DDIM with k steps, for trained checkpoints of one task.

Samples ``--samples`` (the paper's 16) per test configuration for ``--configs`` configurations of the task's
test shards, as ``tohgs.methods.predict`` does, one torch thread. Needs a finished training run
(``results/models/<task>/*.pt``). Writes ``benchmarks/results/sampling.json``.
"""

from __future__ import annotations

import argparse
import glob
import json
import platform
import time
from pathlib import Path

import torch

from tohgs.data.maps import MapDataset
from tohgs.models.diffusion import sample
from tohgs.models.checkpoint import load_component

REPO = Path(__file__).resolve().parent.parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--task", default="placing")
    ap.add_argument("--models", default=str(REPO / "results" / "models"))
    ap.add_argument("--shards", default=str(REPO / "results" / "maps" / "{task}" / "test" / "shard-*.zarr"))
    ap.add_argument("--configs", type=int, default=2)
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--ddim", type=int, nargs="+", default=[20, 50, 100])
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "sampling.json"))
    args = ap.parse_args()
    torch.set_num_threads(1)
    torch.backends.mha.set_fastpath_enabled(False)  # as tohgs.methods.predict
    shards = sorted(glob.glob(args.shards.format(task=args.task)))
    if not shards:
        raise SystemExit(f"no test shards match {args.shards.format(task=args.task)}: run the workflow first")
    data = MapDataset(shards, per="config")
    contact, _ = load_component(Path(args.models) / args.task / "contact_diffuser.pt", "cpu")
    grasp, _ = load_component(Path(args.models) / args.task / "grasp_diffuser.pt", "cpu")
    s = args.samples
    out = {"benchmark": "sampling", "machine": platform.processor() or platform.machine(), "task": args.task,
           "threads": 1, "samples_per_config": s, "configs": min(args.configs, len(data)),
           "unit": "seconds per sample (one contact map, or one grasp)", "samplers": {}}
    for sampler, steps in [("ddpm", 1000)] + [("ddim", k) for k in args.ddim]:
        t_contact = t_grasp = 0.0
        gen = torch.Generator().manual_seed(0)
        for i in range(out["configs"]):
            item = data[i]
            pts = torch.as_tensor(item["points"])[None].expand(s, -1, -1)
            nrm = torch.as_tensor(item["normals"])[None].expand(s, -1, -1)
            d_i = torch.as_tensor(item["d_init"])[None].expand(s, -1)
            d_g = torch.as_tensor(item["d_goal"])[None].expand(s, -1)
            t0 = time.perf_counter()
            with torch.no_grad():
                cond = contact.condition(pts, nrm, d_i, d_g)
            x = sample(lambda xt, tt: contact(xt, tt, cond), (s, pts.shape[1]), contact.diffusion, sampler, steps, gen)
            cmap = (x.clamp(-1, 1) + 1) / 2
            t_contact += time.perf_counter() - t0
            t0 = time.perf_counter()
            with torch.no_grad():
                gcond = grasp.condition(pts, nrm, cmap)
            sample(lambda xt, tt: grasp(xt, tt, gcond), (s, grasp.dim), grasp.diffusion, sampler, steps, gen)
            t_grasp += time.perf_counter() - t0
        n = out["configs"] * s
        key = f"{sampler} {steps} steps"
        out["samplers"][key] = {"contact_map_s": round(t_contact / n, 4), "grasp_s": round(t_grasp / n, 4),
                                "contact_map_and_grasp_s": round((t_contact + t_grasp) / n, 4)}
        print(key, out["samplers"][key], flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
