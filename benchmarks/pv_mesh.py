"""PV voxelising the target's convex parts (``evaluation.pv_mesh: collision``, the official code's choice)
against its repaired mesh (``mesh``), on the same hands: one prediction store of a finished run (the Dataset
row by default), every kept grasp at its initial pose, both PVs per grasp. Writes JSON with the machine and
commit: the mean PV per task and mesh (cm^3), the share of grasps with PV > 0, the per-grasp differences
and the share of grasps whose QR verdict on PV changes.

    python benchmarks/pv_mesh.py results/ [--method dataset] [--out benchmarks/results/pv_mesh_dataset.json]

PV alone (no SD): about a minute per method on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
from pathlib import Path

import numpy as np


def pv_both(results: Path, task: str, method: str) -> dict[str, np.ndarray]:
    """(G,) PV of every kept grasp of ``results/predictions/<task>/<method>.zarr``, m^3, per PV mesh."""
    from tohgs.data.predictions import read_predictions
    from tohgs.data.scenes import read_scenes
    from tohgs.geometry.grasp import pose_matrix
    from tohgs.hand import HandAssets
    from tohgs.metrics.evaluate import PV_MESHES, _object_assets
    from tohgs.metrics.quality import penetration_volume

    arrays, attrs = read_predictions(results / "predictions" / task / f"{method}.zarr")
    hand = HandAssets.load(results / "hand" / "hand.npz")
    faces = np.asarray(hand.closed_faces)
    scenes = {}  # the test targets' scene stores (every target's are there)
    for p in sorted((results / "scenes" / task).glob("*.zarr")):
        sc = read_scenes(p)
        scenes[sc.object] = sc
    caches: dict[str, dict] = {m: {} for m in PV_MESHES}
    out: dict[str, list[float]] = {m: [] for m in PV_MESHES}
    vocab = list(attrs["objects"])
    for i in range(len(arrays["object_id"])):
        name = vocab[int(arrays["object_id"][i])]
        c = int(arrays["config_index"][i])
        kept = np.asarray(arrays["kept"][i], bool)
        if not kept.any():
            continue
        T = pose_matrix(scenes[name].target_init_pose[c])
        local = (hand.vertices(arrays["grasp_init"][i][kept]) - T[:3, 3]) @ T[:3, :3]
        for m in PV_MESHES:
            obj = _object_assets(results / "objects", name, 0.001, caches[m], None, m)
            out[m] += np.atleast_1d(penetration_volume(local, faces, obj.voxels, 0.001)).tolist()
    return {m: np.asarray(v) for m, v in out.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", type=Path)
    ap.add_argument("--method", default="dataset")
    ap.add_argument("--tasks", nargs="+", default=["placing", "stacking", "shelving"])
    ap.add_argument("--qr-pv-cm3", type=float, default=3.0, help="QR's PV bound (evaluation.qr), cm^3")
    ap.add_argument("--out", type=Path, default=None,
                    help="default benchmarks/results/pv_mesh_<method>.json")
    a = ap.parse_args()
    a.out = a.out or Path(f"benchmarks/results/pv_mesh_{a.method}.json")
    report = {"machine": platform.processor() or platform.machine(), "method": a.method,
              "commit": subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip(),
              "tasks": {}}
    for task in a.tasks:
        pv = pv_both(a.results, task, a.method)
        cm3 = {m: v * 1e6 for m, v in pv.items()}
        diff = cm3["collision"] - cm3["mesh"]
        report["tasks"][task] = {
            "grasps": int(len(diff)),
            **{f"pv_{m}_cm3": float(v.mean()) for m, v in cm3.items()},
            **{f"penetrating_{m}": float((v > 0).mean()) for m, v in cm3.items()},
            "diff_mean_cm3": float(diff.mean()), "diff_abs_median_cm3": float(np.median(np.abs(diff))),
            "diff_abs_max_cm3": float(np.abs(diff).max()), "diff_nonzero": float((diff != 0).mean()),
            # grasps whose PV verdict of QR (PV < a.qr_pv_cm3) differs between the two meshes
            "qr_pv_flips": float(((cm3["collision"] < a.qr_pv_cm3) != (cm3["mesh"] < a.qr_pv_cm3)).mean()),
        }
        print(task, json.dumps(report["tasks"][task]))
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(report, indent=1) + "\n")


if __name__ == "__main__":
    main()
