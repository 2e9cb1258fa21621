"""Benchmark of GraspTTA at test time: seconds per adapted grasp (GraspCVAE's sample, then the test-time
adaptation, :mod:`tohgs.grasps.tta`) and seconds per configuration of F-GraspTTA's multi-start ICP.

Self-contained: the components are built at the config's default sizes (the schema's; the cost does not
depend on the weights) and the object is a synthetic cloud of ``--points`` points (the default maps'
512), S = ``--samples`` grasps at once (the paper's 16), ``--steps`` adaptation steps (the paper's 300),
on the CPU with one thread and, where there is one, on CUDA. Writes ``benchmarks/results/tta.json``
(or ``--out``).
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np
import torch
import trimesh

from tohgs.config import validate_config
from tohgs.data.batch import Batch
from tohgs.geometry.maps import sample_surface
from tohgs.geometry.registration import ICPSettings, register
from tohgs.grasps.tta import TTASettings, adapt
from tohgs.hand import load_hand
from tohgs.models.component import build_component

REPO = Path(__file__).resolve().parent.parent


def _batch(points: np.ndarray, normals: np.ndarray, s: int, device: torch.device) -> Batch:
    p = torch.as_tensor(points, dtype=torch.float32, device=device)[None].expand(s, -1, -1)
    n = torch.as_tensor(normals, dtype=torch.float32, device=device)[None].expand(s, -1, -1)
    zeros = torch.zeros(p.shape[:2], device=device)
    return Batch(points=p, normals=n, d_init=zeros, d_goal=zeros, scene=p, scene_normals=n,
                 goal_transform=torch.eye(4, device=device).expand(s, 4, 4))


def run(device: torch.device, args, cfg: dict) -> dict:
    hand = load_hand("anny").to(device)
    comps = cfg["components"]
    cvae = build_component("grasp_cvae", comps["grasp_cvae"]["network"]).to(device).eval()
    net = build_component("contact_net", comps["contact_net"]["network"]).to(device).eval()
    mesh = trimesh.creation.capsule(height=0.08, radius=0.03)
    pts, nrm = sample_surface(mesh, args.points, np.random.default_rng(0))
    batch = _batch(pts, nrm, args.samples, device)
    gen = torch.Generator().manual_seed(0)
    settings = TTASettings(steps=args.steps, search_every=args.search_every)
    timings = []
    for rep in range(args.repeats + 1):
        if device.type == "cuda":
            torch.cuda.synchronize()
        t0 = time.perf_counter()
        coarse = cvae.sample_grasps(batch, "ddim", 1, gen)
        adapt(hand, coarse, batch.points, net, 100.0, settings)
        if device.type == "cuda":
            torch.cuda.synchronize()
        if rep:  # the first run warms up
            timings.append(time.perf_counter() - t0)
    per_grasp = float(np.median(timings)) / args.samples
    return {"seconds_per_adapted_grasp": round(per_grasp, 5), "seconds_per_step_per_grasp": round(per_grasp / args.steps, 7),
            "seconds_per_configuration": round(per_grasp * args.samples, 4)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--points", type=int, default=512)
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--search-every", type=int, default=TTASettings.search_every)
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "tta.json"))
    args = ap.parse_args()
    torch.set_num_threads(1)
    cfg = validate_config({})
    out = {"benchmark": "tta", "machine": platform.processor() or platform.machine(), "threads": 1,
           "points": args.points, "samples_per_config": args.samples, "adaptation_steps": args.steps,
           "unit": "seconds", "devices": {}}
    devices = [torch.device("cpu")] + ([torch.device("cuda")] if torch.cuda.is_available() else [])
    for dev in devices:
        name = dev.type if dev.type == "cpu" else torch.cuda.get_device_name(0)
        out["devices"][name] = run(dev, args, cfg)
        print(name, out["devices"][name], flush=True)
    rng = np.random.default_rng(1)
    mesh = trimesh.creation.capsule(height=0.08, radius=0.03)
    src, _ = sample_surface(mesh, args.points // 2, rng)
    tgt, _ = sample_surface(mesh, args.points // 2, rng)
    tgt = tgt @ trimesh.transformations.random_rotation_matrix(rng.random(3))[:3, :3].T + [0.2, 0.1, 0.0]
    t0 = time.perf_counter()
    icp = ICPSettings(**cfg["prediction"]["filter"]["icp"])
    for _ in range(args.repeats):
        register(src, tgt, icp)
    out["icp_seconds_per_configuration"] = round((time.perf_counter() - t0) / args.repeats, 4)
    print("icp", out["icp_seconds_per_configuration"], flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
