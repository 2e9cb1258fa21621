"""Benchmark of the prior-grasp stage, before and after in one run: accepted grasps per CPU-minute, the
filter's pass rates per check, and the accepted grasps' energies, PV, SD and diversity.

Runs the stage's own code (:func:`tohgs.grasps.prior.make_prior_grasps`, then the filter) per object as a
fresh workflow job would (no cache: the SDF grid and the surface voxels are built in the job), one torch
thread, timed with the process's CPU clock. Two variants, interleaved object by object and seed by seed so
that the machine's load falls on both alike:

- ``before``: the synthesis of the default config at 557fbf2 (300 annealing iterations on every hand
  vertex with the step decayed every 8 and the temperature every 2, then 200 polishing iterations; the
  same computation, bit for bit, as that commit's) and SD simulated for every grasp;
- ``after``: the config's settings (``--config``, default ``config/config.yaml``) as they are now;
  ``--batches`` adds ``after-b<N>`` variants, the same at other batch sizes (grasps per object).

Both filter with the config's thresholds. Objects come from the objects stage (``results/objects``; run
``snakemake --cores 2 results/objects/<name>`` first). Writes ``benchmarks/results/prior.json``; with
``--keep DIR`` also the filtered stores, as ``DIR/<variant>/seed<k>/<object>.zarr`` (for the prior figure,
:func:`tohgs.viz.grasps.plot_prior_grasps`).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from tohgs.config import load_config
from tohgs.grasps.filter import CHECKS, SCREEN_KEYS
from tohgs.grasps.prior import filter_prior_grasps, make_prior_grasps
from tohgs.hand import load_hand

sys.path.insert(0, str(Path(__file__).resolve().parent))
from base_commit import cpu_name  # noqa: E402

REPO = Path(__file__).resolve().parent.parent

#: The synthesis settings that differ in the default config at 557fbf2 (the "before" variant).
BEFORE = {"iterations": 300, "refine_iterations": 200, "step_decay_every": 8, "temperature_decay_every": 2,
          "anneal_vertices": 1.0}


def machine() -> dict:
    """The machine and the checkout the numbers come from."""

    def git(*a: str) -> str:
        return subprocess.run(["git", *a], cwd=REPO, capture_output=True, text=True).stdout.strip()

    return {"machine": platform.machine(), "cpu": cpu_name(), "cpus": os.cpu_count(), "load_avg_start": os.getloadavg()[0],
            "commit": git("rev-parse", "HEAD"), "dirty": bool(git("status", "--porcelain", "--untracked-files=no")),
            "torch": torch.__version__}


def per_vertex_spread(vertices: np.ndarray) -> float:
    """Mean over pairs of grasps of the mean per-vertex distance between the two hands, m (DS / V, the
    evaluation's diversity per vertex), for (S, V, 3) hands; NaN for fewer than two."""
    s = len(vertices)
    if s < 2:
        return float("nan")
    total = sum(float(np.linalg.norm(vertices[i + 1:] - vertices[i], axis=-1).mean(1).sum()) for i in range(s - 1))
    return total / (s * (s - 1) / 2)


def quantiles(x: np.ndarray, scale: float) -> list[float] | None:
    """The 10th, 50th and 90th percentiles of ``x * scale`` (None when empty)."""
    x = np.asarray(x, dtype=np.float64)
    x = x[np.isfinite(x)]
    return [round(float(q) * scale, 4) for q in np.quantile(x, [0.1, 0.5, 0.9])] if len(x) else None


def run_one(obj: Path, hand, cfg: dict, variant: str, seed: int, tmp: Path, keep: Path | None = None) -> tuple[dict, dict]:
    """One object through synthesis, metrics and the filter: (timing and counts, the accepted grasps' arrays);
    the filtered store is copied to ``keep/<variant>/seed<seed>/<object>.zarr`` when ``keep`` is given."""
    pg, metrics = cfg["prior_grasps"], cfg["metrics"]
    synthesis = {**pg["synthesis"], **(BEFORE if variant == "before" else {})}
    if variant.startswith("after-b"):
        synthesis["batch"] = int(variant.removeprefix("after-b"))
    screen = None if variant == "before" or pg["simulate"] == "all" else {k: pg["filter"][k] for k in SCREEN_KEYS}
    name = obj.name
    raw, filtered = tmp / f"{name}-{variant}-{seed}.zarr", tmp / f"{name}-{variant}-{seed}-f.zarr"
    cpu0, wall0 = time.process_time(), time.perf_counter()
    g = make_prior_grasps(obj, hand, "anny", synthesis, pg["sdf"], metrics["sd"], metrics["voxel_pitch"],
                          pg["plane_direction"]["bricks" if name.startswith("brick-") else "objects"], seed, raw,
                          cache_dir=None, screen=screen)
    f = filter_prior_grasps(raw, pg["filter"], filtered)
    cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    if keep is not None:
        dest = keep / variant / f"seed{seed}" / f"{name}.zarr"
        shutil.rmtree(dest, ignore_errors=True)
        shutil.copytree(filtered, dest)
    ok = f.passed
    with torch.no_grad():
        verts = hand(torch.as_tensor(f.pose[ok])).vertices.numpy() if ok.any() else np.zeros((0, 1, 3))
    row = {"object": name, "variant": variant, "seed": seed, "grasps": len(g), "accepted": int(ok.sum()),
           "simulated": int(np.isfinite(g.sd).sum()), "cpu_s": round(cpu, 2), "wall_s": round(wall, 2),
           **{f"{k}_wall_s": round(v, 2) for k, v in g.attrs["timing"].items()},
           **{f"{k}_cpu_s": round(v, 2) for k, v in g.attrs["cpu_timing"].items()},
           "rejections": f.attrs["rejections"], "spread_cm": round(per_vertex_spread(verts) * 100, 3)}
    arrays = {"fc": f.energies["fc"][ok], "dis": f.energies["dis"][ok], "pen": f.energies["pen"][ok],
              "pv": f.pv[ok], "sd": f.sd[ok], "contact_distance": f.contact_distance[ok],
              **{f"pass_{c}": f.flags[c] for c in CHECKS}, "simulated": np.isfinite(f.sd)}
    return row, arrays


def summarize(rows: list[dict], arrays: list[dict]) -> dict:
    """Totals, the filter's pass rate per check (SD's among the simulated grasps) and the accepted grasps'
    distributions (10th, 50th, 90th percentiles) of one variant."""
    cat = {k: np.concatenate([a[k] for a in arrays]) for k in arrays[0]}
    simulated = cat["simulated"]
    rates = {c: round(float(cat[f"pass_{c}"][simulated].mean() if c == "sd" else cat[f"pass_{c}"].mean()), 4)
             for c in CHECKS}
    accepted, cpu = sum(r["accepted"] for r in rows), sum(r["cpu_s"] for r in rows)
    spread = [r["spread_cm"] for r in rows if np.isfinite(r["spread_cm"])]
    return {"accepted_per_cpu_minute": round(accepted / (cpu / 60), 1), "accepted": accepted,
            "grasps": sum(r["grasps"] for r in rows), "simulated": sum(r["simulated"] for r in rows),
            "cpu_s": round(cpu, 1), "acceptance": round(accepted / sum(r["grasps"] for r in rows), 4),
            "pass_rate": {**rates, "sd_of": "simulated grasps"},
            "accepted_quantiles_10_50_90": {"e_fc": quantiles(cat["fc"], 1), "e_dis_mm": quantiles(cat["dis"], 1e3),
                                            "e_pen_mm": quantiles(cat["pen"], 1e3), "pv_cm3": quantiles(cat["pv"], 1e6),
                                            "sd_cm": quantiles(cat["sd"], 100),
                                            "contact_distance_mm": quantiles(cat["contact_distance"], 1e3)},
            "spread_cm_mean_over_runs": round(float(np.mean(spread)), 3) if spread else None}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--objects", default="brick-cube,pb-duck,pb-rand-063")
    ap.add_argument("--seeds", default="0,1", help="global seeds; each gives other grasps of every object")
    ap.add_argument("--config", default=str(REPO / "config" / "config.yaml"))
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "prior.json"))
    ap.add_argument("--keep", default=None, help="folder to keep the filtered stores in")
    ap.add_argument("--batches", default="", help="other batch sizes of the after variant, e.g. 256")
    args = ap.parse_args()
    cfg = load_config(args.config)
    torch.set_num_threads(1)
    hand = load_hand("anny")
    objects = [REPO / "results" / "objects" / n for n in args.objects.split(",")]
    for obj in objects:
        if not (obj / "mesh.obj").is_file():
            raise SystemExit(f"{obj}: not prepared; run `snakemake --cores 2 results/objects/{obj.name}` first")
    info = machine()
    variants = ["before", "after"] + [f"after-b{int(b)}" for b in args.batches.split(",") if b]
    rows: dict[str, list[dict]] = {v: [] for v in variants}
    arrays: dict[str, list[dict]] = {v: [] for v in variants}
    with tempfile.TemporaryDirectory() as tmp:
        k = 0
        for seed in (int(s) for s in args.seeds.split(",")):
            for obj in objects:
                order = variants if k % 2 == 0 else variants[::-1]  # alternate who runs first
                k += 1
                for variant in order:
                    row, arr = run_one(obj, hand, cfg, variant, seed, Path(tmp), Path(args.keep) if args.keep else None)
                    rows[variant].append(row)
                    arrays[variant].append(arr)
                    print(json.dumps(row), flush=True)
    summary = {v: summarize(rows[v], arrays[v]) for v in rows}
    speedup = {v: round(summary[v]["accepted_per_cpu_minute"] / summary["before"]["accepted_per_cpu_minute"], 2)
               for v in variants[1:]}
    out = {"benchmark": "prior_grasps", **info, "torch_threads": 1,
           "command": " ".join(["python benchmarks/bench_prior.py", *sys.argv[1:]]),
           "before": {"synthesis": BEFORE, "simulate": "all"},
           "after": {"synthesis": {k: cfg["prior_grasps"]["synthesis"][k] for k in BEFORE},
                     "simulate": cfg["prior_grasps"]["simulate"]},
           "filter": cfg["prior_grasps"]["filter"], "batch": cfg["prior_grasps"]["synthesis"]["batch"],
           "speedup_accepted_per_cpu_minute": speedup, "summary": summary, "runs": [r for v in variants for r in rows[v]]}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps({k: out[k] for k in ("speedup_accepted_per_cpu_minute", "summary")}, indent=2))


if __name__ == "__main__":
    main()
