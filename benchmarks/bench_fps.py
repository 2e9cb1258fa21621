"""Benchmark of PointNet++'s farthest-point sampling: seconds per forward pass of the backbone with the levels
after the first taking their centres as a prefix of the previous level's farthest-point order
(:class:`tohgs.models.pointnet2.SetAbstraction`, ``ordered``) against sampling every level anew, and of the
sampling loop alone per level, at the default's and the paper's ContactDiffuser sizes (batch 8 x 2048
points; the paper's levels sample 512 then 128 centres, the default's 128 then 32).

The outputs of the two paths are the same bit for bit (checked here, and in tests/test_pointnet2.py). One
torch thread, as the workflow's jobs; ``--device cuda`` times the GPU where there is one. Writes
``benchmarks/results/fps_<device>.json``.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import torch

from tohgs.models.pointnet2 import PointNet2, PointNet2Config, farthest_point_sample

REPO = Path(__file__).resolve().parent.parent
SIZES = {
    "default": ((128, 0.02, 16, (32, 32, 64)), (32, 0.05, 16, (64, 64, 128)), (0, 0.0, 0, (128, 256))),
    "paper": ((512, 0.02, 32, (64, 64, 128)), (128, 0.04, 64, (128, 128, 256)), (0, 0.0, 0, (256, 512, 512))),
}
FP = {"default": ((128,), (128,), (128, 128)), "paper": ((256, 256), (256, 256), (512, 512))}


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize()


def _time(fn, device: torch.device, repeats: int) -> float:
    fn()  # warm up
    _sync(device)
    t = time.perf_counter()
    for _ in range(repeats):
        fn()
    _sync(device)
    return (time.perf_counter() - t) / repeats


def _forward(net: PointNet2, xyz: torch.Tensor, feats: torch.Tensor, ordered: bool):
    """The backbone's set-abstraction levels, with or without the prefix shortcut."""
    xs, fs = [xyz], [feats]
    for level, sa in enumerate(net.sa):
        x, f = sa(xs[-1], fs[-1], ordered=ordered and level > 0 and net.sa[level - 1].npoint > 0)
        xs.append(x)
        fs.append(f)
    return xs, fs


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--points", type=int, default=2048)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    device = torch.device(args.device)
    g = torch.Generator().manual_seed(0)
    xyz = (torch.rand(args.batch, args.points, 3, generator=g) * 0.1).to(device)
    feats = torch.rand(args.batch, args.points, 4, generator=g).to(device)
    out = {"device": str(device), "machine": platform.processor() or platform.machine(), "batch": args.batch,
           "points": args.points, "threads": 1, "sizes": {}}
    for name, sa in SIZES.items():
        torch.manual_seed(0)
        net = PointNet2(PointNet2Config(in_channels=4, sa=sa, fp=FP[name])).to(device).eval()
        with torch.no_grad():
            a, b = _forward(net, xyz, feats, True), _forward(net, xyz, feats, False)
            assert all(torch.equal(p, q) for p, q in zip(a[0] + a[1][1:], b[0] + b[1][1:])), "paths differ"
            new = _time(lambda: _forward(net, xyz, feats, True), device, args.repeats)
            old = _time(lambda: _forward(net, xyz, feats, False), device, args.repeats)
            loops = {}
            n = args.points
            for npoint, *_ in sa:
                if npoint:
                    cloud = xyz[:, :n]
                    loops[f"fps_{n}_to_{npoint}"] = _time(lambda: farthest_point_sample(cloud, npoint), device,
                                                          args.repeats)
                    n = npoint
        out["sizes"][name] = {"seconds_set_abstraction_prefix": new, "seconds_set_abstraction_resampled": old,
                              "speedup": old / new, "seconds_fps_loop": loops}
        print(name, json.dumps(out["sizes"][name]))
    path = REPO / "benchmarks" / "results" / f"fps_{device.type}.json"
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(out, indent=1) + "\n")
    tmp.replace(path)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
