"""Benchmark of the cost per object of two object sources: YCB everyday objects against pybullet_data's
procedural ``random_urdfs`` blobs, measured in the same run.

For each object (the sources interleaved, so that load drift on a shared machine hits both alike) it runs
the stages' own library code with the settings of a config (default: the embedded default):

1. the objects stage, :func:`tohgs.assets.objects.prepare_object` (repair, rescale, CoACD decomposition;
   no cache, so the decomposition is computed): CPU seconds and the number of convex parts;
2. the prior grasps, :func:`tohgs.grasps.prior.make_prior_grasps` and the filter: CPU seconds (of which
   the object's SDF grid, timed on its own first: its cost grows with the mesh's faces) and the accepted
   grasps;
3. SD, :class:`tohgs.metrics.quality.DisplacementSimulator`: CPU milliseconds per grasp, timed one
   simulation at a time over all the object's synthesised grasps and over its accepted ones (the grasps
   an evaluation sees are mostly in contact, which costs more than a hand that misses the object).

The objects are the ones a run would draw: the first ``--n`` of the default config's ``random_urdfs``
draw, and a seeded draw of ``--n`` from the curated YCB list (``objects.sources.ycb.count``), unless
``--ycb`` / ``--random`` name them. One torch thread; CPU time is the process's clock (CoACD's threads
included). Writes ``benchmarks/results/sources.json``: one row per object and, per source, the median
and mean of each column.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from tohgs.assets.mesh import object_mesh
from tohgs.assets.objects import prepare_object
from tohgs.assets.sources import ObjectSpec, pybullet_random_candidates, select_objects, ycb_candidates
from tohgs.config import load_config
from tohgs.grasps.filter import filter_prior_grasps
from tohgs.grasps.prior import SDFSettings, make_prior_grasps, object_sdf
from tohgs.hand import load_hand
from tohgs.metrics.quality import DisplacementSimulator, SDSettings, sd_gravity
from tohgs.settings import settings_from

REPO = Path(__file__).resolve().parent.parent


def choose_objects(cfg: dict[str, Any], n: int, ycb: str | None, random: str | None) -> list[ObjectSpec]:
    """The benchmark's objects, YCB and random_urdfs alternating: named ones, or the ones a run draws."""
    objects = cfg["objects"]
    if random:
        pool = {s.name: s for s in pybullet_random_candidates()}
        rand = [pool[f"pb-rand-{k}"] for k in random.split(",")]
    else:
        drawn = select_objects(objects, cfg["seed"])
        rand = [s for s in drawn if s.name.startswith("pb-rand-")][:n]
    if ycb:
        ycbs = ycb_candidates(ycb.split(","))
    else:
        only_ycb = {"pybullet_data": {"random_urdfs": 0, "named": 0}, "bricks": {"count": 0, "scale": 1.0},
                    "dir": {"path": None, "count": 0}, "ycb": {"count": n, "names": None}}
        ycbs = select_objects({**objects, "sources": only_ycb}, cfg["seed"])
    out: list[ObjectSpec] = []
    for k in range(max(len(ycbs), len(rand))):
        out += ycbs[k:k + 1] + rand[k:k + 1]
    return out


def sd_times(hand, pose: np.ndarray, obj_dir: Path, settings: SDSettings) -> np.ndarray:
    """CPU seconds of one SD simulation per grasp of (B, 51) ``pose`` on the object in ``obj_dir``."""
    import trimesh

    mesh = trimesh.load(obj_dir / "mesh.obj", force="mesh", process=False)
    with torch.no_grad():
        verts = hand(torch.as_tensor(pose, dtype=hand.rest_vertices.dtype)).vertices.cpu().numpy().astype(np.float64)
    faces = hand.closed_faces.cpu().numpy()
    centre = np.asarray(mesh.vertices).mean(0)
    gravity = sd_gravity(settings, verts[:, hand.assets.palm_ids].mean(1), centre)
    out = np.empty(len(pose))
    with DisplacementSimulator(obj_dir / "collision.obj", centre, settings) as sim:
        for i in range(len(pose)):
            c0 = time.process_time()
            sim.displacement(verts[i], faces, gravity=gravity[i])
            out[i] = time.process_time() - c0
    return out


def collision_vertices(path: Path) -> int | None:
    """The number of vertices of all convex parts in an objects-stage ``collision.obj`` (None if absent):
    Bullet's convex-mesh contacts cost more with more vertices, not only with more parts."""
    if not path.is_file():
        return None
    return sum(1 for line in path.read_text().splitlines() if line.startswith("v "))


def summary(rows: list[dict[str, Any]], key: str) -> dict[str, float]:
    vals = [r[key] for r in rows if r[key] is not None and np.isfinite(r[key])]
    if not vals:
        return {"median": float("nan"), "mean": float("nan")}
    return {"median": round(float(statistics.median(vals)), 3), "mean": round(float(np.mean(vals)), 3)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default=str(REPO / "config" / "config.yaml"))
    ap.add_argument("--n", type=int, default=6, help="objects per source (default 6)")
    ap.add_argument("--ycb", default=None, help="comma-separated YCB stems instead of the seeded draw")
    ap.add_argument("--random", default=None, help="comma-separated random_urdfs numbers (063,101) instead of the draw")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "sources.json"))
    args = ap.parse_args()
    cfg = load_config(args.config)
    o, pg, metrics = cfg["objects"], cfg["prior_grasps"], cfg["metrics"]
    sd_settings = settings_from(SDSettings, metrics["sd"])
    specs = choose_objects(cfg, args.n, args.ycb, args.random)
    torch.set_num_threads(1)
    hand = load_hand("anny")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        objects_dir = Path(tmp) / "objects"
        for spec in specs:
            obj_dir = objects_dir / spec.name
            c0, w0 = time.process_time(), time.perf_counter()
            meta = prepare_object(spec, obj_dir, o["size"], 1.0, o["decomposition"], o["density"], cfg["seed"], None)
            row: dict[str, Any] = {"object": spec.name, "source": "ycb" if spec.source == "ycb" else "random_urdfs",
                                   "status": meta["status"], "reason": meta["reason"],
                                   "objects_cpu_s": round(time.process_time() - c0, 2),
                                   "objects_wall_s": round(time.perf_counter() - w0, 2),
                                   "n_collision_parts": meta.get("n_collision_parts"),
                                   "collision_vertices": collision_vertices(obj_dir / "collision.obj"),
                                   "extents_cm": [round(100 * e, 1) for e in meta.get("extents", [])]}
            if meta["status"] != "ok":
                rows.append({**row, "mesh_faces": None, "prior_cpu_s": None, "sdf_cpu_s": None, "grasps": 0,
                             "accepted": 0, "sd_ms_all": None, "sd_ms_accepted": None})
                print(rows[-1], flush=True)
                continue
            raw_store, filtered = Path(tmp) / f"{spec.name}.zarr", Path(tmp) / f"{spec.name}-f.zarr"
            cache = Path(tmp) / "cache" / spec.name  # the SDF grid timed on its own, then read from here
            mesh = object_mesh(objects_dir, spec.name)
            c0, w0 = time.process_time(), time.perf_counter()
            object_sdf(mesh, settings_from(SDFSettings, pg["sdf"]), cache)
            sdf_cpu, sdf_wall = time.process_time() - c0, time.perf_counter() - w0
            raw = make_prior_grasps(obj_dir, hand, "anny", pg["synthesis"], pg["sdf"], metrics["sd"],
                                    metrics["voxel_pitch"], pg["plane_direction"]["objects"], cfg["seed"], raw_store,
                                    cache_dir=cache)
            kept = filter_prior_grasps(raw_store, pg["filter"], filtered)
            timing = raw.attrs["timing"]
            row.update(prior_cpu_s=round(time.process_time() - c0, 1), prior_wall_s=round(time.perf_counter() - w0, 1),
                       sdf_cpu_s=round(sdf_cpu, 2), sdf_wall_s=round(sdf_wall, 2),
                       synthesis_wall_s=round(timing["synthesis"], 2), metrics_wall_s=round(timing["metrics"], 2),
                       mesh_faces=len(mesh.faces), grasps=len(raw), accepted=int(kept.passed.sum()))
            t = sd_times(hand, raw.pose, obj_dir, sd_settings)
            passed = np.asarray(kept.passed, dtype=bool)
            row.update(sd_ms_all=round(1e3 * float(np.median(t)), 2), sd_ms_all_mean=round(1e3 * float(t.mean()), 2),
                       sd_ms_accepted=round(1e3 * float(np.median(t[passed])), 2) if passed.any() else None,
                       sd_ms_accepted_mean=round(1e3 * float(t[passed].mean()), 2) if passed.any() else None)
            rows.append(row)
            print(row, flush=True)
    keys = ["objects_cpu_s", "n_collision_parts", "collision_vertices", "mesh_faces", "prior_cpu_s", "sdf_cpu_s", "accepted", "sd_ms_all",
            "sd_ms_accepted"]
    per_source = {}
    for src in ("ycb", "random_urdfs"):
        sel = [r for r in rows if r["source"] == src]
        ok = [r for r in sel if r["status"] == "ok"]
        per_source[src] = {"objects": len(sel), "accepted_objects": len(ok),
                           **{k: summary(ok, k) for k in keys}}
    out = {"benchmark": "sources", "machine": platform.processor() or platform.machine(), "torch_threads": 1,
           "config": str(Path(args.config).relative_to(REPO)) if Path(args.config).is_relative_to(REPO) else args.config,
           "seed": cfg["seed"], "time": time.strftime("%Y-%m-%d %H:%M:%S"),
           "note": "CPU seconds of the process; objects stage uncached; SD in CPU ms per simulation (median per "
                   "object, then median/mean over objects); the machine was shared, so wall times are noisy",
           "per_source": per_source, "objects": rows}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps(per_source, indent=2))


if __name__ == "__main__":
    main()
