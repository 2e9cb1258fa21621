"""How far from a grasp that holds may a hand be and still hold? On a finished run.

The Dataset row's test grasps (``results/predictions/<task>/dataset.zarr``: each test configuration's own
ground-truth grasps, which pass QR about 90 % of the time) are moved by random errors of a growing scale and
evaluated as the evaluation stage does (the config's SD, PV and hand settings, the task's scene stores).
At scale k every grasp gets, independently: a translation of N(0, (k x 1 cm)^2) per axis and a rotation
by the axis-angle vector N(0, (k x 0.1 rad)^2 I) in the hand's own frame (the same motion at the initial and
the goal pose, so the goal hand is still the initial one carried with the object), and N(0, (k x 0.1
rad)^2) on each finger joint's axis-angle. Per scale: the hands' mean vertex distance to their grasp (cm;
median and mean over grasps) and the table's numbers (QR %, the share failing SD, PV avg cm^3, Init and Goal
OPP %, TS). Scale 0 is the Dataset row itself (its metrics must equal the run's).

It says how close to a holding grasp a generator must put the hand: the GraspDiffuser given a ground-truth
map puts it a median 5.3 cm from that map's grasp on the test configurations, and 2.1 cm on its training
configurations after four times its steps, where it holds no more often (docs/history.md, issue 50).

    python benchmarks/hold_tolerance.py --results results --tasks placing [--scales 0 0.25 0.5 1 2] \\
        [--configfile config/config.yaml] [--out benchmarks/results/hold_tolerance.json]

About 1 minute per scale and task on one core (Placing: 32 configurations of 16 grasps). The perturbed
stores and their metrics are kept under ``<results>/hold_tolerance/`` and reused by a second call.
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
from train_fit import summary  # noqa: E402

from tohgs.config import evaluation_sd_settings, load_configs, run_cache_dir  # noqa: E402
from tohgs.data.predictions import read_predictions, write_predictions  # noqa: E402
from tohgs.hand import HandAssets  # noqa: E402
from tohgs.hand.layout import TRANSLATION_DIM  # noqa: E402
from tohgs.hand.rotations import axis_angle_to_matrix, matrix_to_axis_angle  # noqa: E402
from tohgs.io import atomic_path, write_json  # noqa: E402
from tohgs.metrics.evaluate import evaluate_predictions  # noqa: E402
from tohgs.metrics.quality_thresholds import QualityThresholds  # noqa: E402

TRANSLATION_SD = 0.01  # m at scale 1
ROTATION_SD = 0.1  # rad at scale 1, the wrist's rotation vector per axis
FINGER_SD = 0.1  # rad at scale 1, per finger-joint axis-angle component


def perturb(init: np.ndarray, goal: np.ndarray, scale: float, rng: np.random.Generator
            ) -> tuple[np.ndarray, np.ndarray]:
    """(G, 51) initial and goal grasps moved by one random error each (module docstring), the same in the
    hand's own frame at both poses. With the global rotation R about the rest wrist joint j
    (vertices R (v - j) + j + t), the motion (dR, dt) in the hand's frame gives R' = R dR and t' = t + R dt:
    carried by any rigid motion of the object, the initial hand's perturbed copy is the goal's."""
    g = len(init)
    d_t = rng.normal(0.0, scale * TRANSLATION_SD, (g, 3))
    d_r = rng.normal(0.0, scale * ROTATION_SD, (g, 3))
    d_f = rng.normal(0.0, scale * FINGER_SD, (g, init.shape[1] - TRANSLATION_DIM - 3))
    d_rot = axis_angle_to_matrix(torch.from_numpy(d_r)).numpy()  # (G, 3, 3)
    out = []
    for grasp in (init, goal):
        t, r = grasp[:, :TRANSLATION_DIM], grasp[:, TRANSLATION_DIM:TRANSLATION_DIM + 3]
        rot = axis_angle_to_matrix(torch.from_numpy(r.astype(np.float64))).numpy()
        new_r = matrix_to_axis_angle(torch.from_numpy(rot @ d_rot)).numpy()
        new_t = t + np.einsum("gij,gj->gi", rot, d_t)
        out.append(np.concatenate([new_t, new_r, grasp[:, TRANSLATION_DIM + 3:] + d_f], axis=1))
    return out[0], out[1]


def vertex_distance(hand: HandAssets, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(G,) mean distance (m) between the vertices of the (G, 51) grasps ``a`` and ``b``."""
    return np.linalg.norm(hand.vertices(a) - hand.vertices(b), axis=-1).mean(-1)


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", type=Path, default=Path("results"), help="the run's results folder")
    ap.add_argument("--tasks", nargs="+", default=["placing"])
    ap.add_argument("--scales", nargs="+", type=float, default=[0.0, 0.25, 0.5, 1.0, 2.0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--configfile", nargs="+", default=[str(REPO / "config/config.yaml")],
                    help="the run's config files (SD, PV and hand settings)")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks/results/hold_tolerance.json")
    a = ap.parse_args(argv)
    run = a.results.resolve().parent
    cfg = load_configs(a.configfile, base_dir=run)
    t = QualityThresholds(**cfg["evaluation"]["qr"])
    hand_path = a.results / "hand/hand.npz"
    hand = HandAssets.load(hand_path)
    out: dict = {"benchmark": "hold_tolerance", "commit": commit_label(), "cpu": cpu_name(),
                 "configfile": a.configfile, "seed": a.seed,
                 "sd_at_scale_1": {"translation_m": TRANSLATION_SD, "rotation_rad": ROTATION_SD,
                                   "finger_rad": FINGER_SD}, "tasks": {}}
    for ti, task in enumerate(a.tasks):
        source = a.results / f"predictions/{task}/dataset.zarr"
        if not source.exists():
            raise SystemExit(f"{source}: missing (run the workflow's dataset row for {task} first)")
        arrays, attrs = read_predictions(source)
        c, s, d = arrays["grasp_init"].shape
        init = arrays["grasp_init"].reshape(-1, d).astype(np.float64)
        goal = arrays["grasp_goal"].reshape(-1, d).astype(np.float64)
        work = a.results / "hold_tolerance" / task
        work.mkdir(parents=True, exist_ok=True)
        levels = []
        for li, scale in enumerate(a.scales):
            rng = np.random.default_rng([a.seed, ti, li])
            new_init, new_goal = perturb(init, goal, scale, rng)
            dist = vertex_distance(hand, new_init, init)
            store, metrics = work / f"scale-{scale:g}.zarr", work / f"scale-{scale:g}.parquet"
            if not store.exists():
                write_predictions({**arrays, "grasp_init": new_init.reshape(c, s, d),
                                   "grasp_goal": new_goal.reshape(c, s, d)},
                                  {**attrs, "method": f"dataset-perturbed-{scale:g}"}, store)
            if not metrics.exists():
                ev = cfg["evaluation"]
                rows = evaluate_predictions(store, sorted((a.results / f"scenes/{task}").glob("*.zarr")),
                                            a.results / "objects", a.results / "objects/supports/supports.json",
                                            hand, evaluation_sd_settings(cfg), cfg["metrics"]["voxel_pitch"],
                                            run_cache_dir(cfg, run), progress=True, pv_mesh=ev["pv_mesh"],
                                            sd_hand=ev["sd_hand"])
                with atomic_path(metrics) as tmp:
                    rows.to_parquet(tmp, index=False)
            level = {"scale": scale, "vertex_cm_median": 100 * float(np.median(dist)),
                     "vertex_cm_mean": 100 * float(dist.mean()), **summary(pd.read_parquet(metrics), t)}
            levels.append(level)
            print(f"{task} scale {scale:g}: " + " ".join(f"{k} {v:.3f}" for k, v in level.items() if k != "scale"))
        out["tasks"][task] = levels
    write_json(a.out, out)
    return out


if __name__ == "__main__":
    main()
