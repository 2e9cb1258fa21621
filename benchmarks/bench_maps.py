"""Benchmark of the maps: samples per second (two distance maps and one contact map per sample) with the
k-d tree the stage uses, side by side with brute-force all-pairs distances, at the default and the
paper's sizes. Clouds are random points in a 10 cm box (object), a 50 cm slab (scene) and a hand-sized box
(1609 hand vertices). Writes ``benchmarks/results/maps.json``.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

from tohgs.geometry.maps import nearest_distance, nearest_distance_brute, normalised_map

REPO = Path(__file__).resolve().parent.parent


def one_sample(fn, obj, obj_goal, scene, hand) -> None:
    normalised_map(fn(obj, scene), 30.0)
    normalised_map(fn(obj_goal, scene), 30.0)
    normalised_map(fn(obj, hand), 100.0)


def rate(fn, sizes: tuple[int, int], n: int, rng: np.random.Generator) -> float:
    n_obj, n_scene = sizes
    clouds = [(rng.random((n_obj, 3)) * 0.1, rng.random((n_obj, 3)) * 0.1 + [0.3, 0, 0],
               rng.random((n_scene, 3)) * [0.5, 0.5, 0.02], rng.random((1609, 3)) * [0.18, 0.1, 0.05]) for _ in range(n)]
    t = time.perf_counter()
    for c in clouds:
        one_sample(fn, *c)
    return n / (time.perf_counter() - t)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--n", type=int, default=20)
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "maps.json"))
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    out = {"benchmark": "maps", "machine": platform.processor() or platform.machine(), "unit": "samples/s",
           "sample": "D_init + D_goal + contact map", "sizes": {}}
    for name, sizes in (("default (N 512, N_s 2048)", (512, 2048)), ("paper (N 2048, N_s 6000)", (2048, 6000))):
        kd = rate(nearest_distance, sizes, args.n, rng)
        brute = rate(nearest_distance_brute, sizes, max(2, args.n // 4), rng)
        out["sizes"][name] = {"kd_tree": round(kd, 1), "brute_force": round(brute, 1), "speed_up": round(kd / brute, 1)}
        print(name, out["sizes"][name], flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
