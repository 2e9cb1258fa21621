"""Benchmark of the prior-grasp stage: accepted grasps per CPU-minute, and PV / SD evaluations per second.

Runs the stage's own code (:func:`tohgs.grasps.prior.make_prior_grasps` and the filter) with the settings
of a config file (default ``config/config.yaml``) on objects prepared by the objects stage
(``results/objects``; run the workflow first), one torch thread, and times each phase with the process's
CPU clock. Writes ``benchmarks/results/prior.json``.
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from pathlib import Path

import torch
import yaml

from tohgs.grasps.prior import filter_prior_grasps, make_prior_grasps
from tohgs.hand import load_hand

REPO = Path(__file__).resolve().parent.parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--objects", default="brick-cube,pb-duck,pb-rand-063")
    ap.add_argument("--config", default=str(REPO / "config" / "config.yaml"))
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "prior.json"))
    args = ap.parse_args()
    cfg = yaml.safe_load(Path(args.config).read_text())
    pg, metrics = cfg["prior_grasps"], cfg["metrics"]
    hand = load_hand("anny")
    torch.set_num_threads(1)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.objects.split(","):
            obj = REPO / "results" / "objects" / name
            if not (obj / "mesh.obj").is_file():
                raise SystemExit(f"{obj}: not prepared; run the workflow's objects stage first")
            cpu0, wall0 = time.process_time(), time.perf_counter()
            raw = make_prior_grasps(obj, hand, "anny", pg["synthesis"], pg["sdf"], metrics["sd"], metrics["voxel_pitch"],
                                    "down" if name.startswith("brick-") else "random", cfg["seed"], Path(tmp) / f"{name}.zarr",
                                    cache_dir=None)
            kept = filter_prior_grasps(Path(tmp) / f"{name}.zarr", pg["filter"],
                                       Path(tmp) / f"{name}-f.zarr")
            cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
            t = raw.attrs["timing"]
            rows.append({"object": name, "grasps": len(raw), "accepted": int(kept.passed.sum()), "cpu_s": round(cpu, 1),
                         "wall_s": round(wall, 1), **{f"{k}_s": round(v, 2) for k, v in t.items()},
                         "metric_evals_per_s": round(len(raw) / t["metrics"], 2),
                         "rejections": kept.attrs["rejections"]})
            print(rows[-1], flush=True)
    accepted = sum(r["accepted"] for r in rows)
    cpu = sum(r["cpu_s"] for r in rows)
    out = {"benchmark": "prior_grasps", "machine": platform.processor() or platform.machine(),
           "torch_threads": 1, "config": str(Path(args.config).relative_to(REPO)) if Path(args.config).is_relative_to(REPO) else args.config,
           "accepted_per_cpu_minute": round(accepted / (cpu / 60), 2), "accepted": accepted,
           "grasps": sum(r["grasps"] for r in rows), "cpu_s": round(cpu, 1),
           "grasp_evaluations_per_s (PV + SD + contact)": round(sum(r["grasps"] for r in rows) / sum(r["metrics_s"] for r in rows), 2),
           "objects": rows}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps({k: v for k, v in out.items() if k != "objects"}, indent=2))


if __name__ == "__main__":
    main()
