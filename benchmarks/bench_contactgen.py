"""Benchmark of ContactGen at test time: seconds per grasp (the sequential CVAE's sample of the contact, part
and direction maps, then the two-stage solver, :mod:`tohgs.grasps.contactgen_solver`).

Self-contained: the CVAE is built at the config's default sizes (the schema's; the cost does not depend on
the weights) and the object is a synthetic capsule cloud of ``--points`` points (the default maps' 512),
S = ``--samples`` grasps (the paper's 16) of each of ``--chunk`` configurations solved as one batch (a
job's ``prediction.chunk``: 8), the solver's steps the schema's defaults
unless ``--global-steps`` / ``--pose-steps`` are given (ContactGen's 200 + 1000), with each of the solver's
distances (``surface``, the default, against ``vertex``, the nearest-vertex proxy it replaced: the same
run, side by side), on the CPU with one thread and, where there is one, on CUDA. ``--base COMMIT`` also
times that commit's solver (:mod:`base_commit`) on the same representations, interleaved with the working
tree's, and records the ratio of their medians and the share of grasps that came out identical. Writes
``benchmarks/results/contactgen.json`` (or ``--out``), with the machine, the CPU and the commit.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch
import trimesh

from tohgs.config import validate_config
from tohgs.data.batch import Batch
from tohgs.geometry.maps import sample_surface
from tohgs.grasps.contactgen_solver import SolverSettings, solve
from tohgs.hand import load_hand
from tohgs.models.component import build_component

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "benchmarks"))
from base_commit import base_module, commit_label, cpu_name, short_commit  # noqa: E402


def run(device: torch.device, args, cfg: dict, distance: str) -> dict:
    hand = load_hand("anny").to(device)
    model = build_component("contact_gen", cfg["components"]["contact_gen"]["network"]).to(device).eval()
    pts, nrm = sample_surface(trimesh.creation.capsule(height=0.08, radius=0.03), args.points, np.random.default_rng(0))
    hands = args.samples * args.chunk  # the configurations of a chunk are solved as one batch, as in a job
    p = torch.as_tensor(pts, dtype=torch.float32, device=device)[None].expand(hands, -1, -1)
    n = torch.as_tensor(nrm, dtype=torch.float32, device=device)[None].expand(hands, -1, -1)
    zeros = torch.zeros(p.shape[:2], device=device)
    batch = Batch(points=p, normals=n, d_init=zeros, d_goal=zeros, scene=p, scene_normals=n,
                  goal_transform=torch.eye(4, device=device).expand(hands, 4, 4))
    solver = {**cfg["prediction"]["contactgen"]}
    if args.global_steps is not None:
        solver["global_steps"] = args.global_steps
    if args.pose_steps is not None:
        solver["pose_steps"] = args.pose_steps
    settings = SolverSettings(**{**solver, "distance": distance})
    gen = torch.Generator().manual_seed(0)
    solvers = {"new": solve}
    if args.base and device.type == "cpu":
        base = base_module("tohgs.grasps.contactgen_solver", args.base)
        solvers["base"] = lambda h, pts, tgt, st: base.solve(h, pts, tgt, base.SolverSettings(**asdict(st)))
    times: dict[str, list[float]] = {k: [] for k in solvers}
    same: list[float] = []
    for rep in range(args.repeats + 1):
        t0 = time.perf_counter()
        target = model.sample_representation(batch, gen)
        sampling = time.perf_counter() - t0
        grasps = {}
        for name, fn in solvers.items():
            if device.type == "cuda":
                torch.cuda.synchronize()
            t0 = time.perf_counter()
            grasps[name], _ = fn(hand, batch.points, target, settings)
            if device.type == "cuda":
                torch.cuda.synchronize()
            if rep:  # the first run warms up
                times[name].append(sampling + time.perf_counter() - t0)
        if rep and "base" in grasps:
            same.append(float((grasps["new"] == grasps["base"]).all(-1).float().mean()))
    timings = times["new"]
    per_grasp = float(np.median(timings)) / hands
    steps = settings.global_steps + settings.pose_steps
    return {"global_steps": settings.global_steps, "pose_steps": settings.pose_steps,
            "seconds_per_grasp": round(per_grasp, 5), "seconds_per_step_per_grasp": round(per_grasp / max(1, steps), 7),
            "seconds_per_configuration": round(per_grasp * args.samples, 4),
            **({"base_seconds_per_configuration": round(float(np.median(times["base"])) / args.chunk, 4),
                "ratio_to_base": round(float(np.median(timings) / np.median(times["base"])), 3),
                "identical_grasps_share": round(float(np.mean(same)), 3)} if "base" in times else {})}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--points", type=int, default=512)
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--chunk", type=int, default=1, help="configurations solved as one batch (prediction.chunk: 8)")
    ap.add_argument("--global-steps", type=int, default=None)
    ap.add_argument("--pose-steps", type=int, default=None)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--distances", nargs="+", default=["vertex", "surface"], choices=["vertex", "surface"])
    ap.add_argument("--base", default=None, help="a commit whose solver is timed beside the working tree's")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "contactgen.json"))
    args = ap.parse_args()
    torch.set_num_threads(1)
    cfg = validate_config({})
    out = {"benchmark": "contactgen", "machine": platform.processor() or platform.machine(), "threads": 1,
           "commit": commit_label(), "cpu": cpu_name(),
           **({"base_commit": short_commit(args.base)} if args.base else {}), "points": args.points,
           "samples_per_config": args.samples, "chunk": args.chunk, "unit": "seconds",
           "devices": {}}
    devices = [torch.device("cpu")] + ([torch.device("cuda")] if torch.cuda.is_available() else [])
    for dev in devices:
        name = dev.type if dev.type == "cpu" else torch.cuda.get_device_name(0)
        out["devices"][name] = {d: run(dev, args, cfg, d) for d in args.distances}
        print(name, out["devices"][name], flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
