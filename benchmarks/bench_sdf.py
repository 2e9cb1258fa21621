"""Benchmark of object signed distances: the torch grid (forward + backward) against the exact distance.

Queries: 128 hands x 2000 points around a brick, as the grasp optimiser asks. Writes
``benchmarks/results/sdf.json`` with queries per second, the grid build time and the accuracy.
"""

from __future__ import annotations

import json
import platform
import time
from pathlib import Path

import numpy as np
import torch

from tohgs.assets.bricks import make_brick
from tohgs.geometry.raycast import exact_signed_distance
from tohgs.geometry.sdf import SDFGrid

REPO = Path(__file__).resolve().parent.parent


def main() -> None:
    mesh = make_brick("arch")
    mesh.apply_translation(-mesh.center_mass)
    t0 = time.perf_counter()
    grid = SDFGrid.build(mesh, spacing=0.002, padding=0.03)
    t_build = time.perf_counter() - t0
    rng = np.random.default_rng(0)
    pts = rng.uniform(mesh.bounds[0] - 0.02, mesh.bounds[1] + 0.02, size=(128 * 2000, 3))
    q = torch.as_tensor(pts, dtype=torch.float32).reshape(128, 2000, 3)
    for _ in range(3):
        grid(q)
    reps = 10
    t0 = time.perf_counter()
    for _ in range(reps):
        x = q.clone().requires_grad_(True)
        grid(x).sum().backward()
    t_grid = (time.perf_counter() - t0) / reps
    t0 = time.perf_counter()
    exact = exact_signed_distance(mesh, pts)
    t_exact = time.perf_counter() - t0
    err = np.abs(grid(q).detach().numpy().ravel() - exact)
    result = {
        "benchmark": "object signed distance queries", "object": "brick-arch", "queries": len(pts),
        "grid_shape": list(grid.values.shape), "grid_spacing_m": grid.spacing, "grid_build_s": t_build,
        "grid_forward_backward_queries_per_s": len(pts) / t_grid, "exact_forward_queries_per_s": len(pts) / t_exact,
        "abs_error_median_m": float(np.median(err)), "abs_error_p99_m": float(np.quantile(err, 0.99)),
        "threads": torch.get_num_threads(), "machine": platform.platform(),
    }
    out = REPO / "benchmarks" / "results" / "sdf.json"
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
