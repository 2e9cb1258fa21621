"""Benchmark of the hand model: forward + backward for a batch of grasp vectors.

Writes ``benchmarks/results/hand_<device>.json``: milliseconds per call (median of repeated calls after a
warm-up) for forward only and forward + backward, on the CPU (all threads of this machine) or CUDA.
Target from the hand issue: at most 50 ms for forward + backward at B = 128 on the CPU.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import time
from pathlib import Path

import torch

from tohgs.hand.model import HandAssets, HandModel

REPO = Path(__file__).resolve().parent.parent


def _time(fn, device: str, repeats: int) -> list[float]:
    out = []
    for _ in range(repeats):
        if device == "cuda":
            torch.cuda.synchronize()
        t0 = time.perf_counter()
        fn()
        if device == "cuda":
            torch.cuda.synchronize()
        out.append(1e3 * (time.perf_counter() - t0))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--model", default="anny")
    ap.add_argument("--assets", default=None, help="a saved HandAssets .npz (default: build/load the backend)")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--batch", type=int, default=128)
    ap.add_argument("--repeats", type=int, default=30)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()

    if args.assets:
        assets = HandAssets.load(args.assets)
    else:
        from tohgs.hand import load_hand_assets

        assets = load_hand_assets(args.model)
    hand = HandModel(assets).to(args.device)
    g = torch.Generator().manual_seed(0)
    pose = (0.3 * torch.randn(args.batch, 51, generator=g)).to(args.device)
    betas = (0.5 * torch.randn(args.batch, 10, generator=g)).to(args.device)

    def fwd(b):
        with torch.no_grad():
            hand(pose, b)

    def fwd_bwd(b):
        p = pose.clone().requires_grad_(True)
        out = hand(p, b)
        (out.vertices.square().sum() + out.joints.square().sum()).backward()

    timings = {}
    for label, b in (("average_shape", None), ("with_betas", betas)):
        for _ in range(5):
            fwd_bwd(b)
        timings[label] = {"forward_ms_median": statistics.median(_time(lambda: fwd(b), args.device, args.repeats)),
                          "forward_backward_ms_median": statistics.median(_time(lambda: fwd_bwd(b), args.device, args.repeats))}
    result = {
        "benchmark": "hand forward (+ backward)", "model": assets.name, "vertices": hand.n_vertices,
        "batch": args.batch, "device": args.device,
        "device_name": torch.cuda.get_device_name() if args.device == "cuda" else platform.processor() or platform.machine(),
        "torch": torch.__version__, "threads": torch.get_num_threads(),
        "repeats": args.repeats, **timings,
    }
    out = Path(args.out) if args.out else REPO / "benchmarks" / "results" / f"hand_{args.device}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
