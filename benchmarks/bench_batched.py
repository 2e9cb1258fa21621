"""Benchmark of the optimising methods batched across the configurations of a prediction job: test
configurations per CPU-second of each optimiser, one configuration at a time (``prediction.chunk: 1``, the
code path of every commit before the batching, which it equals bit for bit) against the configurations
as one batch (``chunk`` = ``--configs``), measured in one run, interleaved, ``--repeats`` times (medians).

- GraspTTA's adaptation (:func:`tohgs.grasps.tta.adapt_many`), S = 16 hands per configuration, the
  schema's ``tta.steps``;
- ContactGen's solver (:func:`tohgs.grasps.contactgen_solver.solve_many`), the schema's steps;
- FLEX (:func:`tohgs.grasps.flex.optimise_many`), the schema's steps, candidates and drops;
- F-GraspTTA's multi-start ICP (open3d, one call per start): :func:`tohgs.geometry.registration.register`
  per configuration against :func:`~tohgs.geometry.registration.register_many` on all of them (which
  registers them one after the other: a vectorised ICP did not pay, its module docstring).

Self-contained: the components are built at the config's default sizes (the schema's; the cost does not
depend on the weights); each configuration is another object (a capsule, a sphere, a box, a cylinder, ...)
of ``--points`` points with a table-and-wall scene cloud of the schema's ``n_scene_points`` and its own
goal transform and random stream. One torch thread; CPU time of the process (``time.process_time``).
Writes ``benchmarks/results/batched.json`` (or ``--out``) with the machine and the commit.
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import time
from pathlib import Path

import numpy as np
import torch
import trimesh

from tohgs.config import validate_config
from tohgs.data.batch import Batch
from tohgs.geometry.contact_parts import PartContact
from tohgs.geometry.maps import sample_surface
from tohgs.geometry.registration import ICPSettings, register, register_many
from tohgs.grasps.contactgen_solver import SolverSettings, solve_many
from tohgs.grasps.flex import FlexSettings, optimise_many
from tohgs.grasps.tta import TTASettings, adapt_many
from tohgs.hand import load_hand
from tohgs.models.component import build_component

REPO = Path(__file__).resolve().parent.parent
SHAPES = (lambda: trimesh.creation.capsule(height=0.08, radius=0.03), lambda: trimesh.creation.icosphere(3, 0.04),
          lambda: trimesh.creation.box((0.05, 0.07, 0.1)), lambda: trimesh.creation.cylinder(radius=0.03, height=0.12),
          lambda: trimesh.creation.box((0.12, 0.04, 0.03)), lambda: trimesh.creation.capsule(height=0.05, radius=0.04),
          lambda: trimesh.creation.cone(radius=0.04, height=0.1), lambda: trimesh.creation.annulus(0.02, 0.045, 0.03))


def configurations(n: int, points: int, scene_points: int) -> list[dict[str, torch.Tensor]]:
    """``n`` configurations: each an object's centred (N, 3) cloud and normals, a table-and-wall scene
    cloud (M, 3) with normals and a goal transform (4, 4) of its own."""
    out = []
    for c in range(n):
        rng = np.random.default_rng(c)
        p, nrm = sample_surface(SHAPES[c % len(SHAPES)](), points, rng)
        p = p - p.mean(0)
        z0 = p[:, 2].min()
        k = scene_points * 2 // 3
        table = np.c_[rng.uniform(-0.2, 0.2, (k, 2)), np.full(k, z0)]
        wall = np.c_[np.full(scene_points - k, 0.07), rng.uniform(-0.2, 0.2, scene_points - k),
                     rng.uniform(z0, z0 + 0.15, scene_points - k)]
        sn = np.r_[np.tile([0.0, 0.0, 1.0], (k, 1)), np.tile([-1.0, 0.0, 0.0], (scene_points - k, 1))]
        goal = np.eye(4)
        a = rng.uniform(-np.pi, np.pi)
        goal[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
        goal[:2, 3] = rng.uniform(-0.2, 0.2, 2)
        out.append({k_: torch.as_tensor(v, dtype=torch.float32) for k_, v in
                    (("points", p), ("normals", nrm), ("scene", np.r_[table, wall]), ("scene_normals", sn), ("goal", goal))})
    return out


def _batch(cfg: dict[str, torch.Tensor], s: int) -> Batch:
    zeros = torch.zeros(1, len(cfg["points"]))
    return Batch(points=cfg["points"][None], normals=cfg["normals"][None], d_init=zeros, d_goal=zeros,
                 scene=cfg["scene"][None], scene_normals=cfg["scene_normals"][None],
                 goal_transform=cfg["goal"][None]).repeat(s)


def chunks(n: int, size: int) -> list[list[int]]:
    return [list(range(i, min(n, i + size))) for i in range(0, n, size)]


def timed(fn) -> float:
    t0 = time.process_time()
    fn()
    return time.process_time() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--configs", type=int, default=4, help="configurations per job (the batch)")
    ap.add_argument("--points", type=int, default=512)
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--only", nargs="*", default=["tta", "contactgen", "flex", "icp"])
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "batched.json"))
    args = ap.parse_args()
    torch.set_num_threads(1)
    cfg = validate_config({})
    pred = cfg["prediction"]
    hand = load_hand("anny")
    comps = cfg["components"]
    confs = configurations(args.configs, args.points, cfg["maps"]["points"]["n_scene_points"])
    s = args.samples
    runs: dict[str, dict] = {}

    if "tta" in args.only:
        torch.manual_seed(0)
        cvae = build_component("grasp_cvae", comps["grasp_cvae"]["network"]).eval()
        net = build_component("contact_net", comps["contact_net"]["network"]).eval()
        tta = TTASettings(**pred["tta"])
        with torch.no_grad():
            coarse = [cvae.sample_grasps(_batch(c, s), "ddim", 1, torch.Generator().manual_seed(i)) for i, c in enumerate(confs)]
        pts = [_batch(c, s).points for c in confs]

        def tta_run(size):
            return lambda: [adapt_many(hand, torch.cat([coarse[i] for i in ch]), torch.cat([pts[i] for i in ch]), net,
                                       100.0, tta, [s] * len(ch)) for ch in chunks(len(confs), size)]
        runs["grasptta_adaptation"] = {"settings": {"steps": tta.steps, "samples": s}, "old": tta_run(1),
                                       "new": tta_run(len(confs))}

    if "contactgen" in args.only:
        torch.manual_seed(0)
        model = build_component("contact_gen", comps["contact_gen"]["network"]).eval()
        solver = SolverSettings(**pred["contactgen"])
        with torch.no_grad():
            reps = [model.sample_representation(_batch(c, s), torch.Generator().manual_seed(i)) for i, c in enumerate(confs)]
        pts = [_batch(c, s).points for c in confs]

        def cg_run(size):
            def go():
                for ch in chunks(len(confs), size):
                    target = PartContact(*(torch.cat([getattr(reps[i], k) for i in ch]) for k in ("contact", "part", "direction")))
                    solve_many(hand, torch.cat([pts[i] for i in ch]), target, solver, [s] * len(ch))
            return go
        runs["contactgen_solver"] = {"settings": {"global_steps": solver.global_steps, "pose_steps": solver.pose_steps,
                                                  "samples": s}, "old": cg_run(1), "new": cg_run(len(confs))}

    if "flex" in args.only:
        torch.manual_seed(0)
        prior = build_component("pose_prior", comps["pose_prior"]["network"]).eval()
        flex = FlexSettings(**{**pred["flex"], "drop_at": tuple(pred["flex"]["drop_at"]),
                               "init_distance": tuple(pred["flex"]["init_distance"])})

        def flex_run(size):
            def go():
                for ch in chunks(len(confs), size):
                    stack = [torch.stack([confs[i][k] for i in ch]) for k in ("points", "normals", "scene", "scene_normals", "goal")]
                    optimise_many(hand, prior, *stack, s, flex, [torch.Generator().manual_seed(i) for i in ch])
            return go
        runs["flex"] = {"settings": {"steps": flex.steps, "batch": flex.batch, "drop_at": list(flex.drop_at), "samples": s},
                        "old": flex_run(1), "new": flex_run(len(confs))}

    if "icp" in args.only:
        icp = ICPSettings(**pred["filter"]["icp"])
        pairs = []
        for i, c in enumerate(confs):  # the object's cloud against half of another sample of it at the goal pose
            rng = np.random.default_rng(100 + i)
            p = c["points"].numpy().astype(np.float64)
            half = p[rng.permutation(len(p))[: len(p) // 2]] + rng.normal(0, 0.0005, (len(p) // 2, 3))
            T = c["goal"].numpy().astype(np.float64)
            pairs.append((p, half @ T[:3, :3].T + T[:3, 3]))
        runs["f_grasptta_icp"] = {"settings": {"starts": 24 * icp.z_turns, "max_iterations": icp.max_iterations},
                                  "old": lambda: [register(a, b, icp) for a, b in pairs],
                                  "new": lambda: register_many(pairs, icp)}

    out = {"benchmark": "batched optimisers", "machine": platform.processor() or platform.machine(),
           "cpu": platform.platform(), "commit": subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO,
                                                                capture_output=True, text=True).stdout.strip(),
           "torch": torch.__version__, "threads": 1, "configurations": args.configs, "points": args.points,
           "unit": "configurations per CPU-second (process time; old: one configuration at a time)", "optimisers": {}}
    for name, run in runs.items():
        variants = [k for k in run if k != "settings"]
        times: dict[str, list[float]] = {k: [] for k in variants}
        for rep in range(args.repeats + 1):  # interleaved; the first round warms up
            for k in variants:
                t = timed(run[k])
                if rep:
                    times[k].append(t)
        med = {k: float(np.median(v)) for k, v in times.items()}
        res = {"settings": run["settings"],
               "cpu_seconds": {k: [round(x, 3) for x in v] for k, v in times.items()},
               "configs_per_cpu_second": {k: round(args.configs / m, 4) for k, m in med.items()},
               "ratio_new_over_old": round(med["old"] / med["new"], 3)}
        out["optimisers"][name] = res
        print(name, json.dumps(res), flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
