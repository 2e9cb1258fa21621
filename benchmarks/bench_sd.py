"""Benchmark of SD (simulation displacement): the one-hand reference against the batch, on the same grasps, in
one run; and where a simulation's time goes.

Objects: default-config objects made by the objects stage's own function (CoACD parts as in a default run);
grasps: the prior stage's synthesis at the default settings (``--grasps`` per object), as synthesised and
pushed 5 mm deeper towards the object (predictions sink into their objects more than optimised grasps);
gravity: the official code's fixed (0, 9.8, 0) and the default ``away_from_palm``; the object at a world pose.

Three ways, interleaved round by round in alternating order (the machine may be shared; compare within a
run only): ``reference`` (:meth:`DisplacementSimulator.displacement` per hand, the protocol, in this
process), ``batch_1`` (:meth:`DisplacementSimulator.displacements`, one worker process) and ``batch_<W>``
(``--workers`` processes), the workers shared by all the cases as in an evaluation job. Every round checks
that all three give the same SD per grasp, bit for bit. Then a phase profile of the protocol's PyBullet
calls (reset, the hand's BVH shape, the object's parts, the bodies, the 35 steps, and the steps again with
1 solver iteration) on the same grasps.

Writes ``benchmarks/results/sd.json``: grasps per second and per CPU-second of each way, the ratios, the
phase profile, the machine (CPU count, load average) and the commit.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from tohgs.assets.mesh import object_mesh
from tohgs.assets.objects import prepare_object
from tohgs.assets.sources import brick_candidates, pybullet_named_candidates, pybullet_random_candidates
from tohgs.config import validate_config
from tohgs.geometry.grasp import pose_matrix
from tohgs.metrics.quality import DisplacementSimulator, SDSettings, SDWorkers, sd_gravity
from tohgs.settings import settings_from

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "benchmarks"))
from base_commit import commit_label  # noqa: E402
POSE = np.array([0.1, -0.2, 0.75, 0.0, 0.0, np.sin(0.4), np.cos(0.4)])  # the object's world pose
PAPER_GRAVITY = (0.0, 9.8, 0.0)


def _cpu() -> float:
    """CPU seconds of this process and its ended children (the pool's workers, once shut down)."""
    return sum(resource.getrusage(who).ru_utime + resource.getrusage(who).ru_stime
               for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))


def prepare(names: list[str], work: Path, n_grasps: int) -> tuple[dict[str, dict], np.ndarray, np.ndarray]:
    """The objects (objects stage, default config) and ``n_grasps`` synthesised grasps of each, as hand
    vertices in the object's mesh frame: ({name: {"dir", "mesh", "hands" (S, V, 3), ...}}, the hand's closed
    faces (F, 3), its palm ids)."""
    import torch

    from tohgs.grasps.prior import SDFSettings, object_sdf, object_seed
    from tohgs.grasps.synthesis import SynthesisSettings, synthesize
    from tohgs.hand import load_hand

    cfg = validate_config({})
    oc, pg = cfg["objects"], cfg["prior_grasps"]
    specs = {c.name: c for c in pybullet_named_candidates() + pybullet_random_candidates() + brick_candidates()}
    hand = load_hand("anny")
    torch.set_num_threads(1)
    out = {}
    for name in names:
        d = work / "objects" / name
        if not (d / "collision.obj").is_file():
            meta = prepare_object(specs[name], d, oc["size"], oc["sources"]["bricks"]["scale"], oc["decomposition"],
                                  oc["density"], cfg["seed"], work / "cache")
            if meta["status"] != "ok":
                raise SystemExit(f"{name}: {meta['reason']}")
        mesh = object_mesh(work / "objects", name)
        syn = settings_from(SynthesisSettings, {**pg["synthesis"], "batch": n_grasps,
                                                "plane_direction": "down" if name.startswith("brick-") else "random"})
        grid = object_sdf(mesh, settings_from(SDFSettings, pg["sdf"]), work / "cache")
        result = synthesize(hand, grid, mesh.vertices, syn, object_seed(cfg["seed"], name), progress=False)
        with torch.no_grad():
            hands = hand(result.pose).vertices.numpy().astype(np.float64)
        parts = sum(1 for line in (d / "collision.obj").read_text().splitlines() if line.startswith("o "))
        out[name] = {"dir": d, "mesh": mesh, "hands": hands, "collision_parts": parts}
        print(f"{name}: {parts} collision parts, {len(hands)} grasps", flush=True)
    return out, np.asarray(hand.closed_faces), np.asarray(hand.assets.palm_ids)


def cases(objects: dict, palm_ids: np.ndarray) -> list[dict]:
    """Every (object, grasp set, gravity) case: world-frame hands (S, V, 3), per-hand gravity (S, 3)."""
    T = pose_matrix(POSE)
    out = []
    for name, o in objects.items():
        centre = np.asarray(o["mesh"].vertices).mean(0)
        palm = o["hands"][:, palm_ids].mean(1, keepdims=True)
        towards = (centre - palm) / np.linalg.norm(centre - palm, axis=-1, keepdims=True)
        for grasps, local in (("synthesised", o["hands"]), ("5 mm deeper", o["hands"] + 0.005 * towards)):
            world = local @ T[:3, :3].T + T[:3, 3]
            for direction in ("fixed", "away_from_palm"):
                settings = SDSettings(gravity_direction=direction, gravity=PAPER_GRAVITY)
                gravity = sd_gravity(settings, world[:, palm_ids].mean(1), T[:3, :3] @ centre + T[:3, 3])
                out.append({"object": name, "grasps": grasps, "gravity": direction, "hands": world,
                            "g": np.array(gravity), "settings": settings, "collision": o["dir"] / "collision.obj",
                            "centre": centre})
    return out


def run_way(way: str, workers: int, case_list: list[dict], faces: np.ndarray) -> np.ndarray:
    """SD of all the cases' hands one way, as an evaluation job does it: a simulator per case, the batch ways'
    worker processes shared by all of them (started and ended inside: part of the cost)."""
    out = []
    with SDWorkers(workers) as pool:
        for case in case_list:
            with DisplacementSimulator(case["collision"], case["centre"], case["settings"], workers=pool) as sim:
                if way == "reference":
                    out.append([sim.displacement(v, faces, POSE, g) for v, g in zip(case["hands"], case["g"])])
                else:
                    out.append(sim.displacements(case["hands"], faces, POSE, case["g"]))
    return np.concatenate(out)


def phase_profile(case_list: list[dict], faces: np.ndarray, per_case: int) -> dict[str, float]:
    """CPU milliseconds per grasp in each PyBullet call of the protocol (the same calls, in the same order,
    as :meth:`DisplacementSimulator.displacement`; the thread's CPU clock, which a busy machine disturbs
    less than the wall clock), on the first ``per_case`` hands of every case; and the 35 steps again with 1
    solver iteration instead of 150."""
    import pybullet as pb

    cid = pb.connect(pb.DIRECT)
    t = dict.fromkeys(("reset", "hand_shape", "hand_body", "object_shape", "object_body", "steps", "steps_1_iteration"), 0.0)
    n = 0
    indices = faces.ravel().tolist()
    try:
        for case in case_list:
            s = case["settings"]
            for v, g in zip(case["hands"][:per_case], case["g"][:per_case]):
                for iterations, key in ((s.solver_iterations, "steps"), (1, "steps_1_iteration")):
                    t0 = time.thread_time()
                    pb.resetSimulation(physicsClientId=cid)
                    pb.setGravity(*g, physicsClientId=cid)
                    pb.setTimeStep(s.time_step, physicsClientId=cid)
                    pb.setPhysicsEngineParameter(numSolverIterations=iterations, physicsClientId=cid)
                    t1 = time.thread_time()
                    hand_col = pb.createCollisionShape(pb.GEOM_MESH, vertices=v.tolist(), indices=indices,
                                                       flags=pb.GEOM_FORCE_CONCAVE_TRIMESH, physicsClientId=cid)
                    t2 = time.thread_time()
                    hand = pb.createMultiBody(0, hand_col, physicsClientId=cid)
                    pb.changeDynamics(hand, -1, lateralFriction=s.hand_friction, restitution=0.0, physicsClientId=cid)
                    t3 = time.thread_time()
                    obj_col = pb.createCollisionShape(pb.GEOM_MESH, fileName=str(case["collision"]), physicsClientId=cid)
                    t4 = time.thread_time()
                    obj = pb.createMultiBody(s.object_mass, obj_col, basePosition=POSE[:3].tolist(),
                                             baseOrientation=POSE[3:].tolist(),
                                             baseInertialFramePosition=case["centre"].tolist(), physicsClientId=cid)
                    pb.changeDynamics(obj, -1, lateralFriction=s.object_friction, restitution=s.object_restitution,
                                      physicsClientId=cid)
                    t5 = time.thread_time()
                    for _ in range(s.steps):
                        pb.stepSimulation(physicsClientId=cid)
                    t6 = time.thread_time()
                    t[key] += t6 - t5
                    if key == "steps":
                        for k, dt in zip(("reset", "hand_shape", "hand_body", "object_shape", "object_body"),
                                         (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4)):
                            t[k] += dt
                n += 1
    finally:
        pb.disconnect(cid)
    ms = {k: round(1000 * v / n, 2) for k, v in t.items()}
    protocol = sum(v for k, v in ms.items() if k != "steps_1_iteration")
    ms["total"] = round(protocol, 2)
    ms["steps_share"] = round(ms["steps"] / protocol, 3)
    ms["grasps"] = n
    return ms


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--objects", default="pb-duck,pb-bunny,pb-rand-063,brick-u-shape,brick-tube")
    ap.add_argument("--grasps", type=int, default=16, help="synthesised grasps per object")
    ap.add_argument("--repeats", type=int, default=2, help="rounds of the three ways")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 2, help="processes of the pooled batch")
    ap.add_argument("--profile-grasps", type=int, default=4, help="grasps per case in the phase profile")
    ap.add_argument("--work", default=None, help="folder for the objects and caches (default: a temporary one)")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "sd.json"))
    args = ap.parse_args()

    load_start = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(args.work or tmp)
        objects, faces, palm_ids = prepare(args.objects.split(","), work, args.grasps)
        case_list = cases(objects, palm_ids)
        ways = [("reference", 1), ("batch_1", 1), (f"batch_{args.workers}", args.workers)]
        wall = {w: [] for w, _ in ways}
        cpu = {w: [] for w, _ in ways}
        n = sum(len(c["hands"]) for c in case_list)
        sds = {}
        for r in range(args.repeats):
            order = ways if r % 2 == 0 else ways[::-1]
            for way, workers in order:
                c0, t0 = _cpu(), time.perf_counter()
                sds[way] = run_way(way, workers, case_list, faces)
                wall[way].append(time.perf_counter() - t0)
                cpu[way].append(_cpu() - c0)
                print(f"round {r}: {way}: {n} grasps in {wall[way][-1]:.1f} s ({cpu[way][-1]:.1f} CPU-s)", flush=True)
            for way, _ in ways[1:]:
                if not np.array_equal(sds[way], sds["reference"]):
                    bad = np.flatnonzero(sds[way] != sds["reference"])
                    raise SystemExit(f"{way} differs from the reference on {len(bad)} of {n} grasps")
        profile = phase_profile(case_list, faces, args.profile_grasps)
        ref = sds["reference"]

    def summary(way: str) -> dict:
        w, c = float(np.median(wall[way])), float(np.median(cpu[way]))
        return {"grasps_per_s": round(n / w, 2), "grasps_per_cpu_s": round(n / c, 2), "wall_s": [round(x, 2) for x in wall[way]],
                "cpu_s": [round(x, 2) for x in cpu[way]]}

    result = {
        "benchmark": "sd", "commit": commit_label(), "machine": platform.processor() or platform.machine(),
        "platform": platform.platform(), "cpu_count": os.cpu_count(), "load_average_start": [round(x, 2) for x in load_start],
        "load_average_end": [round(x, 2) for x in os.getloadavg()],
        "pybullet": __import__("importlib.metadata").metadata.version("pybullet"),
        "objects": {k: {"collision_parts": o["collision_parts"]} for k, o in objects.items()},
        "grasps_per_object": args.grasps, "cases": "objects x {synthesised, 5 mm deeper} x {fixed (0, 9.8, 0), away_from_palm}",
        "grasps": n, "repeats": args.repeats, "workers": args.workers,
        "identical_to_reference": True, "qr_sd_below_2cm": int((ref < 0.02).sum()),
        "sd_cm_quartiles": [round(float(x) * 100, 2) for x in np.percentile(ref, [0, 25, 50, 75, 100])],
        "ways": {way: summary(way) for way, _ in ways},
        "phase_ms_per_grasp": profile,
    }
    base = result["ways"]["reference"]
    for way, _ in ways[1:]:
        result["ways"][way]["ratio_grasps_per_s"] = round(result["ways"][way]["grasps_per_s"] / base["grasps_per_s"], 3)
        result["ways"][way]["ratio_grasps_per_cpu_s"] = round(result["ways"][way]["grasps_per_cpu_s"] / base["grasps_per_cpu_s"], 3)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
