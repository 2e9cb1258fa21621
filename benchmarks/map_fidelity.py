"""Does the GraspDiffuser reproduce the grasp whose contact map it is given? On a finished run.

The paper reads Ours (GT contact) as the two-stage framework's upper bound: given the map of a ground-truth
grasp, the GraspDiffuser should put the hand where that grasp is. This measures how far it does, per task:

- **fidelity**: for ``--items`` task grasps of the training shards and of the test shards (their own
  ground-truth maps, the network frame, no rotation), one grasp sampled per map with the run's sampler
  (``--sampler`` / ``--steps``: the official DDPM 1000 by default) and compared with the map's own grasp:
  the palm centre's error and the mean vertex error (cm), the global rotation's angle (degrees) and the share
  of hands turned by more than 90 degrees from it. The same for an untrained copy of the network (its
  normaliser and hand set as the trained one's, its weights fresh: what reading nothing gives) and, as the
  scale of "a different grasp", the mean vertex error to the nearest *other* task grasp of the same
  configuration. Each checkpoint of ``--models`` (``name=path``) is measured beside the run's on the task it
  was trained for;
- **where the scene collisions come from**: on the run's test predictions, the ``dataset`` row (each
  configuration's ground-truth grasps) against ``--method`` (default ``ours-gt-contact``: the GraspDiffuser on
  those grasps' own maps, sample for sample, :func:`tohgs.methods.base.ground_truth_pick`), each grasp's
  rotation angle from its map's grasp and its Init OPP (the metrics parquet): the mean Init OPP of the hands
  turned by more than 90 degrees and of the others, and the turned hands' share of the row's Init OPP.

    python benchmarks/map_fidelity.py --results results --tasks placing [--items 160] \\
        [--models unclamped=/path/to/grasp_diffuser.pt] [--out benchmarks/results/map_fidelity.json]

About 20 s per task and checkpoint on 2 cores (DDPM 1000 over 2 x 160 maps in one batch).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import torch

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from base_commit import commit_label, cpu_name  # noqa: E402

from tohgs.data.batch import Batch  # noqa: E402
from tohgs.data.maps import MapDataset  # noqa: E402
from tohgs.data.predictions import read_predictions  # noqa: E402
from tohgs.hand import HandAssets, HandModel  # noqa: E402
from tohgs.hand.rotations import axis_angle_to_matrix, rotation_angle  # noqa: E402
from tohgs.io import atomic_path  # noqa: E402
from tohgs.models.checkpoint import load_component  # noqa: E402
from tohgs.models.component import build_component  # noqa: E402

TURNED_DEG = 90.0  # a hand turned by more than this from its map's grasp counts as turned


def grasp_angle(a, b) -> np.ndarray:
    """(S,) the angle between the global rotations of (S, 51) grasps ``a`` and ``b`` (arrays or tensors),
    degrees."""
    a, b = (torch.as_tensor(np.asarray(x), dtype=torch.float64) for x in (a, b))
    return np.degrees(rotation_angle(axis_angle_to_matrix(a[:, 3:6]), axis_angle_to_matrix(b[:, 3:6])).numpy())


def untrained_copy(model):
    """The network of ``model``'s config with fresh weights (seeded), its buffers (normaliser, rest wrist and
    palm) copied: what a GraspDiffuser that learnt nothing samples."""
    torch.manual_seed(0)
    fresh = build_component(model.kind, dict(vars(model.cfg)))
    buffers = dict(model.named_buffers())
    for name, buf in fresh.named_buffers():
        buf.copy_(buffers[name])
    return fresh.eval()


def pick_items(data: MapDataset, items: int, seed: int) -> np.ndarray:
    """``items`` task grasps of ``data`` (all where it has fewer), drawn without replacement from ``seed``."""
    return np.random.default_rng(seed).choice(len(data), min(items, len(data)), replace=False)


def fidelity(model, hand: HandModel, batch: Batch, sampler: str, steps: int, seed: int) -> dict:
    """Errors of one grasp sampled per ground-truth map of the ``batch``'s task grasps (module docstring)."""
    with torch.no_grad():
        pred = model.sample_grasps(batch, sampler, steps, torch.Generator().manual_seed(seed))
        vp, vt = hand(pred).vertices, hand(batch.grasp).vertices
    palm = torch.as_tensor(hand.assets.palm_ids)
    palm_err = ((vp[:, palm].mean(1) - vt[:, palm].mean(1)).norm(dim=-1) * 100).numpy()
    vert_err = ((vp - vt).norm(dim=-1).mean(1) * 100).numpy()
    angle = grasp_angle(pred, batch.grasp)
    return {"items": batch.size, "palm_cm_median": float(np.median(palm_err)),
            "vertex_cm_median": float(np.median(vert_err)), "vertex_cm_mean": float(vert_err.mean()),
            "angle_deg_median": float(np.median(angle)), "turned_pct": float(100 * (angle > TURNED_DEG).mean())}


def nearest_other(hand: HandModel, data: MapDataset, idx: np.ndarray) -> float:
    """Median over the task grasps ``idx`` of ``data`` of the mean vertex error (cm) to the nearest other task
    grasp of its configuration (those with one)."""
    out = []
    with torch.no_grad():
        for i in idx:
            s, row = data.index[i]
            sh = data.shards[s]
            rows = np.flatnonzero(sh.grasp_config == sh.grasp_config[row])
            rows = rows[rows != row]
            if len(rows) == 0:
                continue
            v = hand(torch.as_tensor(sh.grasp[np.r_[row, rows]], dtype=torch.float32)).vertices
            out.append(float(((v[1:] - v[:1]).norm(dim=-1).mean(1) * 100).min()))
    return float(np.median(out)) if out else float("nan")


def collisions(results: Path, task: str, method: str) -> dict:
    """Init OPP of ``method``'s test grasps turned by more than :data:`TURNED_DEG` from their map's grasp
    (the ``dataset`` row's, sample for sample) and of the others (module docstring)."""
    truth, _ = read_predictions(results / f"predictions/{task}/dataset.zarr")
    pred, attrs = read_predictions(results / f"predictions/{task}/{method}.zarr")
    if not (np.array_equal(truth["object_id"], pred["object_id"])
            and np.array_equal(truth["config_index"], pred["config_index"])):
        raise SystemExit(f"{task}: the dataset and {method} predictions are not of the same configurations")
    rows = pd.read_parquet(results / f"metrics/{task}/{method}.parquet")
    vocab = list(attrs["objects"])
    keys = pd.DataFrame({"object": np.repeat([vocab[int(o)] for o in pred["object_id"]], pred["kept"].shape[1]),
                         "config_index": np.repeat(pred["config_index"], pred["kept"].shape[1]),
                         "sample": np.tile(np.arange(pred["kept"].shape[1]), len(pred["object_id"]))})
    keys["angle"] = grasp_angle(pred["grasp_init"].reshape(-1, 51), truth["grasp_init"].reshape(-1, 51))
    m = keys.merge(rows[["object", "config_index", "sample", "init_opp"]], on=["object", "config_index", "sample"])
    turned = m.angle > TURNED_DEG
    return {"grasps": len(m), "turned_pct": float(100 * turned.mean()),
            "init_opp_turned_pct": float(100 * m.init_opp[turned].mean()),
            "init_opp_other_pct": float(100 * m.init_opp[~turned].mean()),
            "turned_share_of_init_opp_pct": float(100 * m.init_opp[turned].sum() / max(m.init_opp.sum(), 1e-12))}


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", type=Path, default=Path("results"), help="the run's results folder")
    ap.add_argument("--tasks", nargs="+", default=["placing"])
    ap.add_argument("--component", default="grasp_diffuser", help="the run's GraspDiffuser component")
    ap.add_argument("--method", default="ours-gt-contact", help="the run's row of that network on ground-truth maps")
    ap.add_argument("--models", nargs="*", default=[], help="more checkpoints to measure, name=path")
    ap.add_argument("--items", type=int, default=160, help="task grasps per split")
    ap.add_argument("--sampler", default="ddpm")
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks/results/map_fidelity.json")
    a = ap.parse_args(argv)
    torch.set_num_threads(2)
    extra = {}  # name -> (model, the task it was trained for)
    for spec in a.models:
        name, _, path = spec.partition("=")
        if not path:
            raise SystemExit(f"--models {spec!r}: expected name=path")
        model, ckpt = load_component(path)
        extra[name] = (model, ckpt["task"])
    hand = HandModel(HandAssets.load(a.results / "hand/hand.npz"))
    out: dict = {"commit": commit_label(), "cpu": cpu_name(), "sampler": a.sampler, "steps": a.steps,
                 "items": a.items, "turned_deg": TURNED_DEG, "tasks": {}}
    for task in a.tasks:
        run_model, _ = load_component(a.results / f"models/{task}/{a.component}.pt", task=task)
        models = {"run": run_model, "untrained": untrained_copy(run_model)}
        models.update({name: model for name, (model, trained) in extra.items() if trained == task})
        res: dict = {}
        for split in ("train", "test"):
            data = MapDataset(sorted((a.results / f"maps/{task}/{split}").glob("shard-*.zarr")), per="grasp")
            idx = pick_items(data, a.items, a.seed)
            batch = Batch.collate([data[i] for i in idx])
            res[split] = {name: fidelity(m, hand, batch, a.sampler, a.steps, a.seed) for name, m in models.items()}
            res[split]["nearest_other_vertex_cm_median"] = nearest_other(hand, data, idx)
            for name in models:
                f = res[split][name]
                print(f"{task} {split:5s} {name:10s} palm {f['palm_cm_median']:5.2f} cm  vertices "
                      f"{f['vertex_cm_median']:5.2f} cm  angle {f['angle_deg_median']:5.1f} deg  turned "
                      f"{f['turned_pct']:4.1f} %")
            print(f"{task} {split:5s} nearest other grasp of the configuration: "
                  f"{res[split]['nearest_other_vertex_cm_median']:.2f} cm")
        if (a.results / f"metrics/{task}/{a.method}.parquet").exists():
            res["collisions"] = collisions(a.results, task, a.method)
            print(f"{task} {a.method}: " + " ".join(f"{k} {v:.2f}" for k, v in res["collisions"].items()))
        out["tasks"][task] = res
    a.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(a.out) as tmp:
        tmp.write_text(json.dumps(out, indent=1) + "\n")
    return out


if __name__ == "__main__":
    main()
