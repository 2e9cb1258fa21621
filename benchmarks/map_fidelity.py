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
  turned by more than 90 degrees and of the others, and the turned hands' share of the row's Init OPP;
- **what a map says of the hand's direction**: how alike (the cosine of the mean-centred maps) each
  sampled hand's own contact map is to the map it was given, for the turned hands and the others; the
  same of the map's own grasp turned by 180 degrees about its palm normal through its palm centre (what a
  map says when nothing else changes); and, per split, for each distinct grasp (object and prior grasp) of
  the shards, the other grasp of the same object whose map is most alike (the configurations' clouds are
  one sample of the object, index for index, so maps of two configurations compare point for point, the
  hands after aligning the clouds): how alike, and how often that twin is turned by more than 90 degrees.

    python benchmarks/map_fidelity.py --results results --tasks placing [--items 160] \\
        [--models unclamped=/path/to/grasp_diffuser.pt] [--out benchmarks/results/map_fidelity.json]

About 20 s per task and checkpoint on 2 cores (DDPM 1000 over 2 x 160 maps in one batch); the twins about 1 s.
"""

from __future__ import annotations

import argparse
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
from tohgs.geometry.hand_object import contact_values  # noqa: E402
from tohgs.hand.assets import rotvec_to_matrix  # noqa: E402
from tohgs.hand.rotations import axis_angle_to_matrix, rotation_angle  # noqa: E402
from tohgs.io import write_json  # noqa: E402
from tohgs.models.checkpoint import load_component  # noqa: E402
from tohgs.models.component import build_component  # noqa: E402

TURNED_DEG = 90.0  # a hand turned by more than this from its map's grasp counts as turned
TWIN_ALIKE = 0.8  # a twin map at least this alike (centred cosine) to a grasp's own counts as near-identical


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


def map_alike(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """(B,) the cosine of the mean-centred (B, N) maps ``a`` and ``b``: 1 for the same map, about 0 for
    unrelated ones (scale-free, so a map's long tail does not dominate)."""
    a, b = a - a.mean(-1, keepdim=True), b - b.mean(-1, keepdim=True)
    return (a * b).sum(-1) / (a.norm(dim=-1) * b.norm(dim=-1)).clamp_min(1e-12)


def hand_map(vertices: torch.Tensor, batch: Batch, alpha: float) -> torch.Tensor:
    """(B, N) the contact map (the shards' definition) of (B, V, 3) hand ``vertices`` on the batch's points."""
    return contact_values(batch.points, vertices.to(batch.points), alpha)[0]


def fidelity(model, hand: HandModel, batch: Batch, sampler: str, steps: int, seed: int, alpha: float) -> dict:
    """Errors of one grasp sampled per ground-truth map of the ``batch``'s task grasps (signed by their
    thumbs for a model with ``thumb_sign``), and how alike each sampled hand's own map is to the one it was
    given, turned hands and others (module docstring)."""
    given = batch  # a GraspDiffuser that reads maps signed by the thumb (thumb_sign) gets them signed
    if getattr(model, "reads_signed_contact", False):
        given = batch.with_contact(model.maps_read(batch.contact, batch.points, batch.grasp, hand))
    with torch.no_grad():
        pred = model.sample_grasps(given, sampler, steps, torch.Generator().manual_seed(seed))
        vp, vt = hand(pred).vertices, hand(batch.grasp).vertices
        alike = map_alike(hand_map(vp, batch, alpha), batch.contact).numpy()
    palm = torch.as_tensor(hand.assets.palm_ids)
    palm_err = ((vp[:, palm].mean(1) - vt[:, palm].mean(1)).norm(dim=-1) * 100).numpy()
    vert_err = ((vp - vt).norm(dim=-1).mean(1) * 100).numpy()
    angle = grasp_angle(pred, batch.grasp)
    turned = angle > TURNED_DEG
    return {"items": batch.size, "palm_cm_median": float(np.median(palm_err)),
            "vertex_cm_median": float(np.median(vert_err)), "vertex_cm_mean": float(vert_err.mean()),
            "angle_deg_median": float(np.median(angle)), "turned_pct": float(100 * turned.mean()),
            "map_alike_turned_median": float(np.median(alike[turned])) if turned.any() else float("nan"),
            "map_alike_other_median": float(np.median(alike[~turned])) if (~turned).any() else float("nan")}


def turned_own_map(hand: HandModel, batch: Batch, alpha: float, degrees: float = 180.0) -> float:
    """Median over the batch's task grasps of how alike the map of the grasp turned by ``degrees`` about
    its palm normal (through its palm centre; the rest palm's plane normal carried by the grasp's global
    rotation) is to the grasp's own map."""
    palm = torch.as_tensor(hand.assets.palm_ids)
    rest = hand.rest_vertices[palm].double()
    normal_rest = torch.linalg.svd(rest - rest.mean(0)).Vh[-1]
    with torch.no_grad():
        v = hand(batch.grasp).vertices.double()
        normal = axis_angle_to_matrix(batch.grasp[:, 3:6].double()) @ normal_rest
        centre = v[:, palm].mean(1, keepdim=True)
        turn = axis_angle_to_matrix(normal * np.radians(degrees))
        turned = centre + (v - centre) @ turn.transpose(1, 2)
        return float(map_alike(hand_map(turned, batch, alpha), batch.contact).median())


def kabsch(target: np.ndarray, source: np.ndarray) -> np.ndarray:
    """(3, 3) the rotation R minimising |R (source - mean) - (target - mean)| of two index-aligned (N, 3)
    clouds."""
    h = (source - source.mean(0)).T @ (target - target.mean(0))
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    return vt.T @ np.diag([1.0, 1.0, d]) @ u.T


def map_twins(data: MapDataset) -> dict:
    """Per distinct grasp (object and prior grasp) of ``data``, the other distinct grasp of the same object
    whose map is most alike (:func:`map_alike` on the index-aligned clouds): the median likeness, the share
    of grasps with a twin at least :data:`TWIN_ALIKE` alike, and the share of those twins turned by more
    than :data:`TURNED_DEG` (the two hands compared after :func:`kabsch` aligns their configurations'
    clouds)."""
    alike, angle = [], []
    for sh in data.shards:
        owner = sh.object_id[sh.grasp_config]
        for obj in np.unique(owner):
            rows = np.flatnonzero(owner == obj)
            rows = rows[np.unique(sh.grasp_prior_index[rows], return_index=True)[1]]
            if len(rows) < 2:
                continue
            maps = torch.as_tensor(np.stack([sh.contact[r] for r in rows]), dtype=torch.float64)
            sim = map_alike(maps[:, None], maps[None]).numpy()
            np.fill_diagonal(sim, -np.inf)
            rot = rotvec_to_matrix(np.stack([sh.grasp[r][3:6] for r in rows]).astype(np.float64))
            clouds = [sh.points[sh.grasp_config[r]].astype(np.float64) for r in rows]
            twins = sim.argmax(1)
            aligned = np.stack([kabsch(clouds[k], clouds[t]) @ rot[t] for k, t in enumerate(twins)])
            alike += sim[np.arange(len(rows)), twins].tolist()
            angle += np.degrees(rotation_angle(torch.as_tensor(rot), torch.as_tensor(aligned)).numpy()).tolist()
    alike, angle = np.asarray(alike), np.asarray(angle)
    near = alike >= TWIN_ALIKE
    return {"grasps": len(alike), "twin_alike_median": float(np.median(alike)) if len(alike) else float("nan"),
            "near_identical_twin_pct": float(100 * near.mean()) if len(alike) else float("nan"),
            "near_identical_twin_turned_pct": float(100 * (angle[near] > TURNED_DEG).mean()) if near.any() else float("nan")}


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
    truth, truth_attrs = read_predictions(results / f"predictions/{task}/dataset.zarr")
    pred, attrs = read_predictions(results / f"predictions/{task}/{method}.zarr")
    if not (np.array_equal(truth["object_id"], pred["object_id"])
            and np.array_equal(truth["config_index"], pred["config_index"])):
        raise SystemExit(f"{task}: the dataset and {method} predictions are not of the same configurations")
    seeds = [dict(a.get("config") or {}).get("seed", 0) for a in (truth_attrs, attrs)]
    if seeds[0] != seeds[1]:  # the ground-truth pick is drawn from the prediction seed: other grasps
        raise SystemExit(f"{task}: {method} was sampled with seed {seeds[1]}, the dataset row with seed {seeds[0]}: "
                         "its ground-truth maps are of other grasps than the dataset row's, sample for sample")
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
            alpha = data.shards[0].alpha_contact
            res[split] = {name: fidelity(m, hand, batch, a.sampler, a.steps, a.seed, alpha) for name, m in models.items()}
            res[split]["nearest_other_vertex_cm_median"] = nearest_other(hand, data, idx)
            res[split]["own_grasp_turned_180_map_alike_median"] = turned_own_map(hand, batch, alpha)
            res[split]["twins"] = map_twins(data)
            for name in models:
                f = res[split][name]
                print(f"{task} {split:5s} {name:10s} palm {f['palm_cm_median']:5.2f} cm  vertices "
                      f"{f['vertex_cm_median']:5.2f} cm  angle {f['angle_deg_median']:5.1f} deg  turned "
                      f"{f['turned_pct']:4.1f} %  its map alike {f['map_alike_other_median']:.2f} (turned "
                      f"{f['map_alike_turned_median']:.2f})")
            print(f"{task} {split:5s} nearest other grasp of the configuration: "
                  f"{res[split]['nearest_other_vertex_cm_median']:.2f} cm; the map's own grasp turned 180 deg: "
                  f"alike {res[split]['own_grasp_turned_180_map_alike_median']:.2f}; twins: "
                  + " ".join(f"{k} {v:.2f}" for k, v in res[split]["twins"].items()))
        if (a.results / f"metrics/{task}/{a.method}.parquet").exists():
            res["collisions"] = collisions(a.results, task, a.method)
            print(f"{task} {a.method}: " + " ".join(f"{k} {v:.2f}" for k, v in res["collisions"].items()))
        out["tasks"][task] = res
    write_json(a.out, out)
    return out


if __name__ == "__main__":
    main()
