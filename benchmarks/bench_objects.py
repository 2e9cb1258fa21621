"""Benchmark of the objects stage: time per object for each step, uncached and cached decomposition.

Writes ``benchmarks/results/objects.json``. Run with ``make benchmark`` (or ``python benchmarks/bench_objects.py``).
Numbers are wall-clock seconds on this machine, one process (one core for most steps; CoACD may use more).
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from tohgs.assets.decomposition import DecompositionSettings, convex_decomposition
from tohgs.assets.mesh import MeshError, load_mesh, normalise, repair_and_validate, choose_scale
from tohgs.assets.bricks import make_brick
from tohgs.assets.objects import object_rng
from tohgs.assets.sources import select_objects
from tohgs.config import load_config

REPO = Path(__file__).resolve().parent.parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--config", default=str(REPO / "config" / "config.yaml"))
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "objects.json"))
    ap.add_argument("--max-objects", type=int, default=12)
    args = ap.parse_args()

    cfg = load_config(args.config)
    specs = select_objects(cfg["objects"], cfg["seed"])
    specs = [s for s in specs if s.source != "bricks"][: args.max_objects // 2] + \
            [s for s in specs if s.source == "bricks"][::3][: args.max_objects - args.max_objects // 2]
    settings = DecompositionSettings(**cfg["objects"]["decomposition"])
    size = cfg["objects"]["size"]
    rows = []
    with tempfile.TemporaryDirectory() as cache:
        for spec in specs:
            t0 = time.perf_counter()
            raw = make_brick(spec.brick) if spec.source == "bricks" else load_mesh(spec.path)
            t1 = time.perf_counter()
            try:
                mesh, _ = repair_and_validate(raw)
            except MeshError as exc:
                rows.append({"name": spec.name, "rejected": str(exc)})
                continue
            t2 = time.perf_counter()
            if spec.source != "bricks":
                mesh = normalise(mesh, choose_scale(mesh.extents, (size["longest_min"], size["longest_max"]),
                                                    (size["thickness_min"], size["thickness_max"]),
                                                    object_rng(cfg["seed"], spec.name)))
            t3 = time.perf_counter()
            parts, method = convex_decomposition(mesh, settings, cache)
            t4 = time.perf_counter()
            _, method2 = convex_decomposition(mesh, settings, cache)
            t5 = time.perf_counter()
            rows.append({"name": spec.name, "faces": int(len(mesh.faces)), "load_s": t1 - t0, "repair_s": t2 - t1,
                         "normalise_s": t3 - t2, "decompose_s": t4 - t3, "decompose_method": method,
                         "decompose_cached_s": t5 - t4, "cached_method": method2, "parts": len(parts)})
            print(f"{spec.name:24s} repair {t2 - t1:6.3f}s  decompose {t4 - t3:6.2f}s ({method}, {len(parts)} parts)"
                  f"  cached {t5 - t4:6.3f}s")
    ok = [r for r in rows if "decompose_s" in r]
    coacd = [r for r in ok if r["decompose_method"] == "coacd"]
    summary = {
        "benchmark": "objects stage, per object",
        "config": str(Path(args.config).relative_to(REPO)) if Path(args.config).is_relative_to(REPO) else args.config,
        "machine": {"platform": platform.platform(), "python": platform.python_version()},
        "n_objects": len(rows),
        "mean_repair_s": float(np.mean([r["repair_s"] for r in ok])),
        "mean_decompose_coacd_s": float(np.mean([r["decompose_s"] for r in coacd])) if coacd else None,
        "mean_decompose_cached_s": float(np.mean([r["decompose_cached_s"] for r in coacd])) if coacd else None,
        "fraction_convex_shortcut": float(np.mean([r["decompose_method"] == "hull" for r in ok])),
        "objects": rows,
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(summary, indent=2) + "\n")
    print(json.dumps({k: v for k, v in summary.items() if k != "objects"}, indent=2))


if __name__ == "__main__":
    main()
