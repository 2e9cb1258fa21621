"""Benchmark of the optimisers' per-hand work, the base commit's code path against the working tree's, in
one run: test configurations per CPU-second and, on the same starts, how well each path's final grasps do
(the same evaluator for both).

- GraspTTA's adaptation (:func:`tohgs.grasps.tta.adapt_many`), S = 16 hands per configuration, the
  schema's ``tta`` settings;
- ContactGen's solver (:func:`tohgs.grasps.contactgen_solver.solve_many`), the schema's steps;
- FLEX (:func:`tohgs.grasps.flex.optimise_many`), the schema's steps, candidates and drops;
- F-GraspTTA's multi-start ICP (:func:`tohgs.geometry.registration.register_many`).

"old" is the base commit's library (:mod:`base_commit`, ``--base``, default the commit before the speed
work), imported next to the working tree's; both get the same networks (built at the schema's sizes,
random weights: the cost does not depend on them), hand model and inputs; all configurations of a path as
one batch (the prediction job's chunk). The problems are made to move, unlike ``bench_batched.py``'s
(whose untrained GraspCVAE puts the hands where no term pulls them, so they hardly move): GraspTTA starts
from relaxed hands turned at random with the palm on a random surface point of the object (as a trained
GraspCVAE's coarse grasps, partly inside the object), ContactGen's targets are the representations of such
hands, FLEX's starts are its own. One torch thread, CPU time (``time.process_time``), ``--repeats``
interleaved rounds after a warm-up round, medians.

Quality, per hand (per returned grasp for FLEX), old against new on the same starts, each evaluated by
the base commit's energy (a fresh nearest-vertex search) and by two metrics: penetration (the deepest
object point inside the hand, behind its nearest vertex's normal, m) and contact distance (the object's
closest point to the hand, m); FLEX's obstacle term and the share of hand points inside the scene cloud
at both poses. Reported: the means, the paired differences' median, how many hands end bit for bit
alike and how many more than 1e-4 (m or rad) apart in some number, and the two-sided Wilcoxon signed-rank p-value of the paired differences (scipy).

Writes ``benchmarks/results/opt_speed.json`` (or ``--out``) with the machine and both commits.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
from pathlib import Path

import numpy as np
import torch
from scipy.stats import wilcoxon

sys.path.insert(0, str(Path(__file__).resolve().parent))
from base_commit import BASE_COMMIT, base_module, short_commit  # noqa: E402
from bench_batched import configurations, timed  # noqa: E402

from tohgs.config import validate_config  # noqa: E402
from tohgs.geometry.contact_parts import PartContact  # noqa: E402
from tohgs.geometry.hand_object import inside_hand, nearest_vertex, vertex_normals  # noqa: E402
from tohgs.grasps.contactgen_solver import SolverSettings, contact_points, representation_of  # noqa: E402
from tohgs.grasps.starts import near_object  # noqa: E402
from tohgs.hand import load_hand  # noqa: E402
from tohgs.models.component import build_component  # noqa: E402

REPO = Path(__file__).resolve().parent.parent


def geometry_metrics(hand, grasp: torch.Tensor, points: torch.Tensor) -> dict[str, np.ndarray]:
    """(B,) penetration (the deepest inside point's distance to its nearest vertex, m; 0 when none is
    inside) and contact distance (the closest object point's distance to the hand, m) of (B, 51) grasps
    on (B, N, 3) points."""
    with torch.no_grad():
        verts = hand(grasp).vertices
        d, idx = nearest_vertex(points, verts)
        inside, _ = inside_hand(points, verts, vertex_normals(verts, hand.closed_faces), idx)
        return {"penetration_m": (inside * d).max(-1).values.numpy(), "contact_distance_m": d.min(-1).values.numpy()}


def paired(old: np.ndarray, new: np.ndarray) -> dict:
    """Means, the median paired difference, and the Wilcoxon signed-rank p-value (1 when all equal)."""
    diff = np.asarray(new, dtype=np.float64) - np.asarray(old, dtype=np.float64)
    p = 1.0 if not np.any(diff != 0) else float(wilcoxon(diff, zero_method="wilcox").pvalue)
    return {"mean_old": float(np.mean(old)), "mean_new": float(np.mean(new)), "median_new_minus_old": float(np.median(diff)),
            "mean_new_minus_old": float(np.mean(diff)), "wilcoxon_p": p, "n": int(len(diff))}


def quality(old: dict[str, np.ndarray], new: dict[str, np.ndarray], g_old: torch.Tensor, g_new: torch.Tensor) -> dict:
    gap = (g_old - g_new).abs().amax(-1)
    return {"hands": int(len(gap)), "bit_for_bit_alike": int((gap == 0).sum()), "apart_over_1e-4": int((gap > 1e-4).sum()),
            "max_abs_grasp_difference": float((g_old - g_new).abs().max()), **{k: paired(old[k], new[k]) for k in old}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--configs", type=int, default=4)
    ap.add_argument("--points", type=int, default=512)
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--base", default=BASE_COMMIT)
    ap.add_argument("--only", nargs="*", default=["tta", "contactgen", "flex", "icp"])
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "opt_speed.json"))
    args = ap.parse_args()
    torch.set_num_threads(1)
    cfg = validate_config({})
    pred, comps = cfg["prediction"], cfg["components"]
    hand = load_hand("anny")
    confs = configurations(args.configs, args.points, cfg["maps"]["points"]["n_scene_points"])
    s, n_cfg = args.samples, args.configs
    sizes = [s] * n_cfg
    pts = torch.cat([c["points"][None].expand(s, -1, -1) for c in confs])
    runs: dict[str, dict] = {}

    if "tta" in args.only:
        tta_new, tta_old = (importlib_module("tohgs.grasps.tta"), base_module("tohgs.grasps.tta", args.base))
        torch.manual_seed(0)
        net = build_component("contact_net", comps["contact_net"]["network"]).eval()
        start = torch.cat([near_object(hand, c["points"], s, i) for i, c in enumerate(confs)])

        def tta_run(mod):
            return lambda: mod.adapt_many(hand, start, pts, net, 100.0, mod.TTASettings(**pred["tta"]), sizes)[0]

        def tta_eval(g):
            terms = tta_old.tta_energy(hand, g, pts, net, 100.0, tta_old.TTASettings(**pred["tta"]), sizes=sizes)
            return {"energy": terms["energy"].detach().numpy(), **geometry_metrics(hand, g, pts)}
        runs["grasptta_adaptation"] = {"settings": {"steps": pred["tta"]["steps"], "samples": s},
                                       "old": tta_run(tta_old), "new": tta_run(tta_new), "eval": tta_eval}

    if "contactgen" in args.only:
        cg_new, cg_old = importlib_module("tohgs.grasps.contactgen_solver"), base_module("tohgs.grasps.contactgen_solver", args.base)
        reps = [representation_of(hand, near_object(hand, c["points"], s, 100 + i), c["points"][None].expand(s, -1, -1), 100.0)
                for i, c in enumerate(confs)]
        target = PartContact(*(torch.cat([getattr(r, k) for r in reps]) for k in ("contact", "part", "direction")))

        def cg_run(mod):
            return lambda: mod.solve_many(hand, pts, target, mod.SolverSettings(**pred["contactgen"]), sizes)[0]

        def cg_eval(g):
            st = cg_old.SolverSettings(**pred["contactgen"])
            with torch.no_grad():
                terms = cg_old.solver_energy(hand, g, pts, target, st, "pose", contact_points(target.contact, SolverSettings(**pred["contactgen"])),
                                             sizes=sizes)
            return {"energy": terms["energy"].numpy(), **geometry_metrics(hand, g, pts)}
        runs["contactgen_solver"] = {"settings": {**pred["contactgen"], "samples": s}, "old": cg_run(cg_old),
                                     "new": cg_run(cg_new), "eval": cg_eval}

    if "flex" in args.only:
        fx_new, fx_old = importlib_module("tohgs.grasps.flex"), base_module("tohgs.grasps.flex", args.base)
        torch.manual_seed(0)
        prior = build_component("pose_prior", comps["pose_prior"]["network"]).eval()
        fs = {**pred["flex"], "drop_at": tuple(pred["flex"]["drop_at"]), "init_distance": tuple(pred["flex"]["init_distance"])}
        stack = [torch.stack([c[k] for c in confs]) for k in ("points", "normals", "scene", "scene_normals", "goal")]

        def fx_run(mod):
            return lambda: mod.optimise_many(hand, prior, *stack, s, mod.FlexSettings(**fs),
                                             [torch.Generator().manual_seed(i) for i in range(n_cfg)])[0]

        def fx_eval(g):
            problem = fx_old.FlexProblem(hand, *stack, fx_old.FlexSettings(**fs))
            with torch.no_grad():
                terms = problem.energy(g, torch.zeros(len(g), prior.cfg.latent))  # the prior term left out: z is not returned
                init, goal = problem.opp(g)
            obj = torch.cat([c["points"][None].expand(s, -1, -1) for c in confs])
            return {"energy_without_prior": (terms["energy"]).numpy(), "obstacle": terms["obstacle"].numpy(),
                    "scene_inside_share": (init + goal).numpy() / 2, **geometry_metrics(hand, g, obj)}
        runs["flex"] = {"settings": {**{k: list(v) if isinstance(v, tuple) else v for k, v in fs.items()}, "samples": s},
                        "old": fx_run(fx_old), "new": fx_run(fx_new), "eval": fx_eval}

    if "icp" in args.only:
        reg_new, reg_old = importlib_module("tohgs.geometry.registration"), base_module("tohgs.geometry.registration", args.base)
        icp = pred["filter"]["icp"]
        pairs = []
        for i, c in enumerate(confs):  # the object's cloud against half of another sample of it at the goal pose
            rng = np.random.default_rng(100 + i)
            p = c["points"].numpy().astype(np.float64)
            half = p[rng.permutation(len(p))[: len(p) // 2]] + rng.normal(0, 0.0005, (len(p) // 2, 3))
            T = c["goal"].numpy().astype(np.float64)
            pairs.append((p, half @ T[:3, :3].T + T[:3, 3]))

        def icp_run(mod):
            return lambda: torch.as_tensor(np.stack([r.transform.reshape(-1) for r in mod.register_many(pairs, mod.ICPSettings(**icp))]))
        runs["f_grasptta_icp"] = {"settings": {"starts": 24 * icp["z_turns"], "max_iterations": icp["max_iterations"]},
                                  "old": icp_run(reg_old), "new": icp_run(reg_new), "eval": None}

    out = {"benchmark": "optimisers per hand: base commit against the working tree", "machine": platform.processor() or platform.machine(),
           "cpu": platform.platform(), "commit": short_commit(), "base_commit": short_commit(args.base), "torch": torch.__version__,
           "threads": 1, "configurations": n_cfg, "samples": s, "points": args.points,
           "unit": "configurations per CPU-second (process time)", "optimisers": {}}
    for name, run in runs.items():
        times: dict[str, list[float]] = {"old": [], "new": []}
        results = {k: run[k]() for k in ("old", "new")}  # the warm-up round, whose grasps are evaluated
        for _ in range(args.repeats):
            for k in ("old", "new"):
                times[k].append(timed(run[k]))
        med = {k: float(np.median(v)) for k, v in times.items()}
        res = {"settings": run["settings"], "cpu_seconds": {k: [round(x, 3) for x in v] for k, v in times.items()},
               "configs_per_cpu_second": {k: round(n_cfg / m, 4) for k, m in med.items()},
               "ratio_new_over_old": round(med["old"] / med["new"], 3)}
        if run["eval"] is not None:
            res["quality"] = quality(run["eval"](results["old"]), run["eval"](results["new"]), results["old"], results["new"])
        else:
            res["quality"] = {"max_abs_transform_difference": float((results["old"] - results["new"]).abs().max())}
        out["optimisers"][name] = res
        print(name, json.dumps(res), flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2) + "\n")


def importlib_module(name: str):
    import importlib

    return importlib.import_module(name)


if __name__ == "__main__":
    main()
