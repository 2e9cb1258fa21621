"""Benchmark of the grasp quality metrics: PV and SD evaluations per second (one process).

Hands: the anny hand in its relaxed preset, its palm (facing -y) placed from 5 mm inside to 15 mm clear
of a generated brick's +y face, so that PV ranges from zero to a few cm^3. Writes ``benchmarks/results/metrics.json``.
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from tohgs.assets.bricks import make_brick
from tohgs.hand import load_hand
from tohgs.metrics.quality import DisplacementSimulator, contact_distance, penetration_volume, surface_voxels

REPO = Path(__file__).resolve().parent.parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--brick", default="cuboid")
    ap.add_argument("--n", type=int, default=64)
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "metrics.json"))
    args = ap.parse_args()

    obj = make_brick(args.brick)
    obj.apply_translation(-obj.center_mass)
    hand = load_hand("anny")
    pose = hand.preset("relaxed", args.n)
    rng = np.random.default_rng(0)
    with torch.no_grad():
        rest = hand(pose).vertices.numpy()
    palm = rest[:, hand.assets.palm_ids].mean(1)  # the palm centre
    offsets = np.stack([np.zeros(args.n), obj.extents[1] / 2 + rng.uniform(-0.005, 0.015, args.n), np.zeros(args.n)], 1)
    verts = rest - palm[:, None] + offsets[:, None]
    faces = hand.assets.closed_faces
    t0 = time.perf_counter()
    vox = surface_voxels(obj)
    t_vox = time.perf_counter() - t0
    t0 = time.perf_counter()
    pv = penetration_volume(verts, faces, vox)
    t_pv = time.perf_counter() - t0
    t0 = time.perf_counter()
    cd = contact_distance(verts, obj)
    t_cd = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "collision.obj"
        obj.export(path)
        with DisplacementSimulator(path, obj.vertices.mean(0)) as sim:
            t0 = time.perf_counter()
            sd = [sim.displacement(v, faces) for v in verts]
            t_sd = time.perf_counter() - t0
    result = {
        "benchmark": "grasp quality metrics", "object": f"brick-{args.brick}", "hands": args.n,
        "hand_vertices": int(verts.shape[1]), "object_surface_voxels": int(len(vox)), "voxelise_s": t_vox,
        "pv_per_s": args.n / t_pv, "contact_distance_per_s": args.n / t_cd, "sd_per_s": args.n / t_sd,
        "pv_cm3_range": [float(pv.min() * 1e6), float(pv.max() * 1e6)],
        "sd_cm_range": [float(min(sd) * 100), float(max(sd) * 100)],
        "contact_mm_range": [float(cd.min() * 1e3), float(cd.max() * 1e3)],
        "machine": platform.platform(),
    }
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
