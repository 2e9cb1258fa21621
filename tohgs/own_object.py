"""Grasp your own object: one mesh through the stages a test object of a run goes through, with the run's
trained models (``tohgs grasp MESH --task placing``).

The mesh is repaired, rescaled and decomposed by the objects stage's own code (:func:`tohgs.assets.objects.
prepare_object`: the same checks, limits and size range as the run's config), placed in configurations of
the task by the scenes stage's generator (:func:`tohgs.sim.scenes.make_scene_store`: the run's support and
its accepted objects as obstacles, or base bricks for Stacking) or read from a scene file (``--scene``), given its distance maps
(:func:`tohgs.data.build_maps.make_map_shard`, a test shard without ground truth), grasped by a method whose
models the run has trained (:func:`tohgs.methods.predict.predict`), and evaluated as the workflow evaluates
(:func:`tohgs.metrics.evaluate.evaluate_predictions`: PV, SD, Init / Goal OPP, the QR verdict). The output
folder is laid out like a run's ``results/`` (``objects/``, ``scenes/<task>/``, ``maps/<task>/test/``,
``predictions/<task>/``, ``metrics/<task>/``, ``hand/``), so the viewer and ``tohgs export`` read it as they
read a run, plus:

- ``export/``: one OBJ hand mesh per grasp and pose (world frame, metres) and the grasps as MANO-layout
  parameters (``<task>_<method>.npz``; docs/formats.md);
- ``grasps.png``: each configuration with the method's first kept hand at the initial and the goal pose;
- ``viewer.html``: a self-contained page of the configurations with their grasps (the run's static viewer);
- ``summary.json``: the object's scale, the configurations, each grasp's metrics and the time of each step;
- ``scene.yaml``: the configurations used, as a scene file (:mod:`tohgs.scene_file`): edit it and pass it back
  with ``--scene`` to grasp the object where you put it.

The object is not trained on: its grasps are the models' answer for an object they never saw, as for the
run's test objects. The folder is written whole or not at all (built beside it, then renamed into place).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import time
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

TASKS = ("placing", "stacking", "shelving")


class OwnObjectError(ValueError):
    """A request ``tohgs grasp`` cannot serve: the message names the file or setting and the fix."""


def _object_name(mesh: Path, taken: set[str]) -> str:
    from tohgs.assets.sources import dir_object_name

    name = dir_object_name(mesh.stem)  # as the objects stage names a user folder's mesh
    if name in taken:
        raise OwnObjectError(f"{mesh}: the run already has an object named {name!r} (its objects.sources.dir); "
                             "rename the file")
    return name


def _models_of(results: Path, task: str, method: str, cfg: dict[str, Any]) -> dict[str, dict[str, Path]]:
    """The chain of methods to predict (the one asked for last), each with its components' checkpoints (by
    component name), after checking that they exist."""
    from tohgs.methods import method_components, of_chain, reads_ground_truth

    methods = cfg["methods"]
    if method not in methods:
        raise OwnObjectError(f"--method {method!r}: not a method of the run's config (it has "
                             f"{', '.join(sorted(methods))})")
    if reads_ground_truth(method, methods):
        raise OwnObjectError(f"--method {method!r} reads the test configurations' ground-truth grasps, which a new "
                             "object does not have; take a method that predicts (e.g. ours)")
    chain = {m: {c: results / "models" / task / f"{c}.pt" for c in method_components(methods[m], cfg["components"])}
             for m in reversed(of_chain(method, methods))}
    missing = [p for models in chain.values() for p in models.values() if not p.is_file()]
    if missing:
        raise OwnObjectError(f"method {method!r} of task {task!r} has no trained models in {results}: "
                             f"{', '.join(map(str, missing))} missing; train them with "
                             f"make reproduce TARGET={missing[0]}")
    return chain


def grasp_own_object(mesh: str | Path, task: str, out: str | Path, results: str | Path = "results",
                     configfiles: list[str | Path] = (), method: str = "ours", n: int = 16, configs: int = 1,
                     formats: tuple[str, ...] = ("obj", "npz"), viewer: bool = True, seed: int | None = None,
                     scene: str | Path | None = None) -> dict[str, Any]:
    """Grasps of ``method`` for the mesh ``mesh`` in ``configs`` configurations of ``task``, written to ``out``
    (module docstring); returns the summary written to ``out/summary.json``.

    Args:
        mesh: an .obj, .stl or .ply file, in any unit (it is rescaled into the run's graspable size range,
            ``objects.size``; the summary gives the scale).
        task: ``placing``, ``stacking`` or ``shelving``.
        out: the output folder (must not exist).
        results: the finished run's ``results/`` folder (its models, objects, supports and hand); a relative
            ``cache_dir`` of the config is taken in the folder above it, the run's, so its caches serve.
        configfiles: the run's config files, in order (none: the embedded default); their settings are used
            throughout (objects, scenes, maps, prediction, evaluation).
        method: a method of the run's config whose models the run has (default ``ours``).
        n: grasps per configuration (the config's ``prediction.samples`` for this run).
        configs: configurations of the task to place the object in (without ``scene``).
        formats: the exports, of ``obj``, ``ply``, ``glb``, ``npz``.
        viewer: write ``viewer.html``.
        seed: the seed of the object's scale, scenes and sampling (default: the run's).
        scene: a scene file (:mod:`tohgs.scene_file`: the configurations, as the ``scene.yaml`` this writes
            holds them) instead of configurations made by the scenes stage's generator.

    Raises:
        OwnObjectError: a bad mesh (not found, refused by the objects stage: the reason), a task or method
            without trained models, an output folder that exists; each names the file and the fix.
        tohgs.scene_file.SceneFileError: a scene file that cannot be used (bodies that reach into each
            other among its reasons), naming the file and the configuration.
    """
    from tohgs.config import load_configs, run_cache_dir
    from tohgs.io import atomic_dir, write_json

    t_start = time.perf_counter()
    mesh, out, results = Path(mesh), Path(out), Path(results)
    if task not in TASKS:
        raise OwnObjectError(f"--task {task!r}: one of {', '.join(TASKS)}")
    if not mesh.is_file():
        raise OwnObjectError(f"{mesh}: no such mesh file")
    if scene is not None and not Path(scene).is_file():
        raise OwnObjectError(f"{scene}: no such scene file")
    if mesh.suffix.lower() not in (".obj", ".stl", ".ply"):
        raise OwnObjectError(f"{mesh}: a mesh file is .obj, .stl or .ply, not {mesh.suffix or 'no suffix'!r}")
    if out.exists():
        raise OwnObjectError(f"{out}: the output folder exists; remove it or name another with --out")
    if n < 1 or configs < 1:
        raise OwnObjectError(f"-n {n}, --configs {configs}: at least 1 each")
    objects_dir = results / "objects"
    supports = objects_dir / "supports" / "supports.json"
    hand_file = results / "hand" / "hand.npz"
    for need in (supports, hand_file):
        if not need.is_file():
            raise OwnObjectError(f"{need}: missing; {results} is not a finished run's results folder "
                                 f"(make reproduce makes one; --results names another)")
    cfg = load_configs(list(configfiles))
    cfg["cache_dir"] = str(run_cache_dir(cfg, results.resolve().parent))  # the run's caches serve
    if seed is not None:  # one seed for the object's scale, its scenes, maps and the sampling
        cfg["seed"] = cfg["prediction"]["seed"] = seed
    chain = _models_of(results, task, method, cfg)
    times: dict[str, float] = {}

    with atomic_dir(out) as tmp:
        tmp = Path(tmp)
        summary = _run(mesh, task, tmp, results, cfg, chain, n, configs, times, scene)
        configs = summary["configurations"]
        tick = time.perf_counter()
        _exports(tmp, task, list(chain)[-1], formats, viewer, configs, cfg)
        times["exports"] = time.perf_counter() - tick
        times["total"] = time.perf_counter() - t_start
        summary["seconds"] = {k: round(v, 2) for k, v in times.items()}
        write_json(tmp / "summary.json", summary)
    log.info("%s: %d grasps of %s in %d configurations -> %s (%.1f s)", mesh.name, len(summary["grasps"]),
             method, configs, out, times["total"])
    return summary


def _run(mesh: Path, task: str, work: Path, results: Path, cfg: dict[str, Any], chain: dict[str, dict[str, Path]],
         n: int, configs: int, times: dict[str, float], scene: str | Path | None = None) -> dict[str, Any]:
    """The stages, in ``work`` (the output folder being built); fills ``times`` per step."""
    import numpy as np

    from tohgs.assets.objects import prepare_object
    from tohgs.assets.sources import ObjectSpec, accepted_objects, task_set
    from tohgs.config import evaluation_sd_settings, job_settings
    from tohgs.data.build_maps import make_map_shard
    from tohgs.hand import HandAssets
    from tohgs.methods.predict import predict
    from tohgs.metrics.evaluate import evaluate_predictions
    from tohgs.metrics.tables import QualityThresholds, quality_ratio
    from tohgs.data.scenes import write_scenes
    from tohgs.scene_file import read_scene_file, write_scene_file
    from tohgs.sim.scenes import make_scene_store

    seed = cfg["seed"]
    objects_dir = work / "objects"
    objects_dir.mkdir()
    run_objects = sorted(p for p in (results / "objects").iterdir() if (p / "meta.json").is_file())
    name = _object_name(mesh, {p.name for p in run_objects})
    ts = task_set(task)
    for p in run_objects:  # the run's objects (obstacles, base bricks) beside the new one, as links
        os.symlink(p.resolve(), objects_dir / p.name, target_is_directory=True)
    os.symlink((results / "objects" / "supports").resolve(), objects_dir / "supports", target_is_directory=True)
    (work / "hand").mkdir()
    os.symlink((results / "hand" / "hand.npz").resolve(), work / "hand" / "hand.npz")

    tick = time.perf_counter()
    spec = ObjectSpec(name, "dir", ts, str(mesh.resolve()))
    size = {**cfg["objects"]["size"]}
    meta = prepare_object(spec, objects_dir / name, size, 1.0, cfg["objects"]["decomposition"],
                          cfg["objects"]["density"], seed, cfg["cache_dir"], cfg["objects"]["limits"])
    times["object"] = time.perf_counter() - tick
    if meta["status"] != "ok":
        raise OwnObjectError(f"{mesh}: refused by the objects stage: {meta['reason']}")
    log.info("%s: scaled by %.4g to extents %s m (the run's size range, objects.size), %d convex parts", mesh.name,
             meta["scale"], np.round(meta["extents"], 3).tolist(), meta["n_collision_parts"])

    tick = time.perf_counter()
    scene_store = work / "scenes" / task / f"{name}.zarr"
    scene_store.parent.mkdir(parents=True)
    supports = objects_dir / "supports" / "supports.json"
    if scene is None:
        pool = accepted_objects([objects_dir / p.name for p in run_objects] + [objects_dir / name], ts)
        scenes = make_scene_store(task, name, pool, objects_dir, supports, {**cfg["scenes"], "n_configs": configs},
                                  seed, scene_store)
    else:
        scenes = read_scene_file(scene, task, name, objects_dir, supports)
        write_scenes(scenes, scene_store)
        configs = len(scenes)
    write_scene_file(scenes, work / "scene.yaml")
    times["scenes"] = time.perf_counter() - tick

    tick = time.perf_counter()
    hand = HandAssets.load(work / "hand" / "hand.npz")
    shard = work / "maps" / task / "test" / "shard-0.zarr"
    shard.parent.mkdir(parents=True)
    make_map_shard(task, "test", 0, 1, [scene_store], [], objects_dir, supports, hand, cfg["maps"]["points"],
                   configs, seed, shard)
    times["maps"] = time.perf_counter() - tick

    tick = time.perf_counter()
    (work / "predictions" / task).mkdir(parents=True)
    base = None
    for m, models in chain.items():
        block = {k: v for k, v in cfg["methods"][m].items() if k != "label"}
        settings = {**job_settings(cfg, m), "samples": n, "threads": max(1, min(os.cpu_count() or 1, 4))}
        store = work / "predictions" / task / f"{m}.zarr"
        predict(task, m, block, [shard], models, settings, store, hand=work / "hand" / "hand.npz", base=base,
                complete=True)
        base = store
    times["grasps"] = time.perf_counter() - tick

    tick = time.perf_counter()
    method = list(chain)[-1]
    rows = evaluate_predictions(base, [scene_store], objects_dir, supports, hand, evaluation_sd_settings(cfg),
                                cfg["metrics"]["voxel_pitch"], cfg["cache_dir"], pv_mesh=cfg["evaluation"]["pv_mesh"],
                                sd_hand=cfg["evaluation"]["sd_hand"])
    (work / "metrics" / task).mkdir(parents=True)
    rows.to_parquet(work / "metrics" / task / f"{method}.parquet", index=False)
    times["evaluation"] = time.perf_counter() - tick

    qr = QualityThresholds(**cfg["evaluation"]["qr"])
    table = rows[["config_index", "sample", "kept", "pv", "sd", "init_opp", "goal_opp"]].copy()
    table["quality"] = qr.passes(rows["pv"], rows["sd"]).to_numpy()  # QR's verdict
    return {"mesh": str(mesh.resolve()), "object": name, "task": task, "method": method,
            "method_label": cfg["methods"][method]["label"], "scale": meta["scale"], "extents_m": meta["extents"],
            "collision_parts": meta["n_collision_parts"], "repairs": meta["repairs"], "configurations": configs,
            "grasps_per_configuration": n, "seed": seed, "qr_thresholds": {"max_pv_m3": qr.max_pv, "max_sd_m": qr.max_sd},
            "qr_percent": quality_ratio(rows, qr), "grasps": json.loads(table.to_json(orient="records"))}


def _exports(work: Path, task: str, method: str, formats: tuple[str, ...], viewer: bool, configs: int,
             cfg: dict[str, Any]) -> None:
    from tohgs.export import export_meshes, export_npz

    store = work / "predictions" / task / f"{method}.zarr"
    for fmt in formats:
        if fmt == "npz":
            export_npz(store, work / "export", hand=work / "hand" / "hand.npz")
        else:
            export_meshes(store, work / "export", fmt, hand=work / "hand" / "hand.npz")
    from tohgs.hand import HandAssets
    from tohgs.viz.predictions import plot_predictions

    scene_stores = sorted((work / "scenes" / task).glob("*.zarr"))
    plot_predictions([store], scene_stores, work / "objects", work / "objects" / "supports" / "supports.json",
                     HandAssets.load(work / "hand" / "hand.npz"), work / "grasps.png", max_configs=configs,
                     labels=[cfg["methods"][method]["label"]])
    if viewer:
        from tohgs.metrics.tables import QualityThresholds
        from tohgs.viz.view import export_html
        from tohgs.viz.view_data import TaskResults

        labels = {method: cfg["methods"][method]["label"]}
        data = TaskResults.from_results(work, task, labels=labels,
                                        thresholds=QualityThresholds(**cfg["evaluation"]["qr"]))
        export_html(data, work / "viewer.html", configs=configs, samples=4, methods=[method])


def main(argv: list[str] | None = None) -> int:
    """``tohgs grasp MESH --task TASK [--results results] [--method ours] [-n 16] [--out DIR]``."""
    ap = argparse.ArgumentParser(prog="tohgs grasp", description=__doc__.split("\n\n")[0].replace("\n", " "))
    ap.add_argument("mesh", type=Path, help="an .obj, .stl or .ply file, in any unit (it is rescaled)")
    ap.add_argument("--task", required=True, choices=TASKS)
    ap.add_argument("--results", type=Path, default=Path("results"), help="the finished run's results folder")
    ap.add_argument("--configfile", type=Path, nargs="*", default=[],
                    help="the run's config files, in order (default: the embedded default)")
    ap.add_argument("--method", default="ours", help="a method of the run whose models exist (default ours)")
    ap.add_argument("-n", type=int, default=16, help="grasps per configuration (default 16)")
    ap.add_argument("--configs", type=int, default=1, help="configurations of the task (default 1)")
    ap.add_argument("--scene", type=Path, default=None,
                    help="a scene file of your configurations (the scene.yaml an output folder holds, edited)")
    ap.add_argument("--format", dest="formats", nargs="*", default=["obj", "npz"], choices=["obj", "ply", "glb", "npz"],
                    help="exports (default obj npz)")
    ap.add_argument("--no-viewer", action="store_true", help="no viewer.html")
    ap.add_argument("--seed", type=int, default=None, help="default: the run's seed")
    ap.add_argument("--out", type=Path, default=None, help="output folder (default grasps/<mesh stem>-<task>)")
    a = ap.parse_args(argv)
    from tohgs.scene_file import SceneFileError

    logging.basicConfig(level=logging.INFO, format="%(message)s")
    out = a.out or Path("grasps") / f"{a.mesh.stem}-{a.task}"
    try:
        s = grasp_own_object(a.mesh, a.task, out, a.results, a.configfile, a.method, a.n, a.configs,
                             tuple(a.formats), not a.no_viewer, a.seed, a.scene)
    except (OwnObjectError, SceneFileError) as err:
        print(f"tohgs grasp: {err}", file=sys.stderr)
        return 2
    secs = s["seconds"]
    print(f"{out}: {len(s['grasps'])} grasps of {s['method_label']} for {s['object']} (scaled by {s['scale']:.4g}), "
          f"QR {s['qr_percent']:.0f} %; {secs['total']:.0f} s (object {secs['object']:.0f}, scenes {secs['scenes']:.0f}, "
          f"maps {secs['maps']:.0f}, grasps {secs['grasps']:.0f}, evaluation {secs['evaluation']:.0f}, "
          f"exports {secs['exports']:.0f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
