"""SD with the full hand against decimated collision hands (``evaluation.sd_hand``, :mod:`tohgs.hand.collision`)
on a finished run's grasps: does the QR of each table row move, and what does a simulation cost?

For each task and method (default: the config's Table 1 rows that have a metric file), the kept grasps of the
run's prediction store (``--limit``: a seeded random subset per task and method) are simulated again, each
with the full hand and with the collision hand of every ``--counts`` triangle count, the variants interleaved
grasp by grasp in one process (their order rotating from grasp to grasp, so that a change in the machine's
load reaches them alike), with the evaluation's SD protocol (the config's ``metrics.sd`` and
``evaluation.sd_gravity``, as the workflow passes them). PV is the run's (``results/metrics/<task>/<method>.parquet``;
the collision hand does not change it). Per task and row, and per row over the tasks:

- ``qr_run`` (the metric file's QR over all its kept grasps, %), ``qr_full`` and ``qr_<count>`` on the
  simulated grasps (PV < ``evaluation.qr.max_pv`` and SD < ``max_sd``, %), and where the run has
  ``results/tables/<--table>.csv``, the row's bootstrap interval of QR (``qr_lo``, ``qr_hi``) and whether
  each ``qr_<count>`` lies in it (a subset's QR is only an estimate of the whole run's: use no ``--limit``
  for the decision);
- ``sd_same_as_run``: the share of grasps whose full-hand SD here equals the metric file's bit for bit (1.0 on
  the machine that ran the evaluation with ``sd_hand: full``; a decimated run's file reads lower);
- per count: ``flips`` (the share of grasps whose SD < ``max_sd`` verdict differs from the full hand's),
  ``to_pass`` and ``to_fail`` (how many flipped each way), ``net`` (``to_pass - to_fail``: the sign of the
  bias), ``sd_abs_diff_median_cm``;
- ``robust_flips``: beside them, the share of the metric file's perturbed SDs (robust SD, where the row has
  them) whose verdict differs from the protocol's: what 0.5 mm of jitter flips;
- ``ms_per_sim`` per variant, wall clock and CPU (this thread's clock, less disturbed by a busy machine),
  and ``ratio`` (the variant's summed time over the full hand's).

    python benchmarks/bench_sd_hand.py --results results --counts 1600 800 [--methods dataset ours] \\
        [--limit 200] [--configfile config/config.yaml] [--out benchmarks/results/sd_hand.json]

About 0.13 s per full-hand simulation on one core of a 2-core machine, 0.08 s at 1,600 triangles: a row of
200 grasps with counts 1600 and 800 takes about 50 s.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "benchmarks"))
from base_commit import commit_label  # noqa: E402


def check_results(results: Path, tasks: list[str]) -> None:
    """Stop with a message naming what a finished run would have and this folder lacks."""
    need = [results / "hand" / "hand.npz", results / "objects"] + [results / sub / t for t in tasks
                                                                    for sub in ("metrics", "predictions", "scenes")]
    missing = [str(p) for p in need if not p.exists()]
    if missing:
        raise SystemExit(f"{results}: not a finished run's results folder (missing {', '.join(missing[:4])}"
                         f"{' ...' if len(missing) > 4 else ''}); run the workflow first (make reproduce) or point "
                         "--results at one")


def grasps_of(results: Path, task: str, method: str, limit: int | None, seed: int) -> tuple[pd.DataFrame, dict]:
    """The kept grasps of a task and method: their metric rows (``object``, ``config_index``, ``sample``, ``pv``,
    ``sd``, ``sd_perturbed``) with columns ``batch`` (the (K, 51) kept grasps of the grasp's configuration at
    the initial pose, posed together as the evaluation poses them: the same vertices bit for bit), ``at`` (the
    grasp's row in it) and ``pose`` (the target's initial pose); a seeded subset of ``limit`` (None: all); and
    the metric file's rows, all of them."""
    from tohgs.data.predictions import read_predictions
    from tohgs.data.scenes import read_scenes

    metrics = pd.read_parquet(results / "metrics" / task / f"{method}.parquet")
    arrays, attrs = read_predictions(results / "predictions" / task / f"{method}.zarr")
    vocab = list(attrs["objects"])
    scenes: dict = {}
    by_key = {}
    for i in range(len(arrays["object_id"])):
        name = vocab[int(arrays["object_id"][i])]
        c = int(arrays["config_index"][i])
        if name not in scenes:
            scenes[name] = read_scenes(results / "scenes" / task / f"{name}.zarr")
        kept = np.asarray(arrays["kept"][i], bool)
        batch = np.asarray(arrays["grasp_init"][i])[kept]
        pose = np.asarray(scenes[name].target_init_pose[c], np.float64)
        for at, k in enumerate(np.flatnonzero(kept)):
            by_key[(name, c, int(k))] = (batch, at, pose)
    kept = metrics[metrics.kept.astype(bool)].reset_index(drop=True)
    keys = list(zip(kept.object.astype(str), kept.config_index.astype(int), kept["sample"].astype(int)))
    absent = [k for k in keys if k not in by_key]
    if absent:
        raise SystemExit(f"{results}/metrics/{task}/{method}.parquet: {len(absent)} kept grasps (e.g. {absent[0]}) are "
                         "not kept grasps of its prediction store: the metric file is of other predictions")
    kept["batch"] = [by_key[k][0] for k in keys]
    kept["at"] = [by_key[k][1] for k in keys]
    kept["pose"] = [by_key[k][2] for k in keys]
    if limit is not None and limit < len(kept):
        rng = np.random.default_rng([seed, zlib.crc32(task.encode()), zlib.crc32(method.encode())])
        pick = np.sort(rng.choice(len(kept), limit, replace=False))
        kept = kept.iloc[pick].reset_index(drop=True)
    return kept, {"metrics": metrics}


def simulate(grasps: pd.DataFrame, hand, variants: dict, settings, objects_dir: Path) -> dict:
    """SD of every grasp with every variant (None: the full hand; else a
    :class:`~tohgs.hand.collision.CollisionHand`), interleaved in this process, the variants' order rotating
    per grasp; ``{"sd": {variant: (G,)}, "wall": {variant: (G,)}, "cpu": {variant: (G,)}}`` (m, s)."""
    from tohgs.assets.mesh import object_mesh
    from tohgs.geometry.grasp import pose_matrix
    from tohgs.metrics.quality import DisplacementSimulator, sd_gravity

    names = list(variants)
    out = {k: {v: np.empty(len(grasps)) for v in names} for k in ("sd", "wall", "cpu")}
    faces = np.asarray(hand.closed_faces)
    sims: dict[str, DisplacementSimulator] = {}
    posed: tuple[int, np.ndarray] = (-1, np.empty(0))  # the last configuration's hands
    try:
        for g, row in enumerate(grasps.itertuples(index=False)):
            name = str(row.object)
            if name not in sims:
                centre = np.asarray(object_mesh(objects_dir, name).vertices).mean(0)
                sims[name] = DisplacementSimulator(objects_dir / name / "collision.obj", centre, settings)
            sim = sims[name]
            if posed[0] != id(row.batch):
                posed = (id(row.batch), hand.vertices(row.batch))
            full = posed[1][row.at]
            T = pose_matrix(row.pose)
            centre = T[:3, :3] @ np.asarray(sim.vertex_mean) + T[:3, 3]
            gravity = sd_gravity(settings, full[None, hand.palm_ids].mean(1), centre)[0]
            for v in names[g % len(names):] + names[:g % len(names)]:
                ch = variants[v]
                hv, f = (full, faces) if ch is None else (ch.pose(full), ch.faces)
                w0, c0 = time.perf_counter(), time.thread_time()
                out["sd"][v][g] = sim.displacement(hv, f, row.pose, gravity)
                out["cpu"][v][g] = time.thread_time() - c0
                out["wall"][v][g] = time.perf_counter() - w0
    finally:
        for sim in sims.values():
            sim.close()
    return out


def compare(grasps: pd.DataFrame, metrics: pd.DataFrame, sims: dict, counts: list[int], max_pv: float,
            max_sd: float) -> dict:
    """The numbers of one task and row (module docstring) from its simulated grasps and its metric rows."""
    from tohgs.metrics.tables import QualityThresholds, quality_ratio

    pv = grasps.pv.to_numpy(float)
    full = sims["sd"]["full"]
    ok_pv = pv < max_pv
    out: dict = {"grasps": int(len(grasps)),
                 "qr_run": quality_ratio(metrics, QualityThresholds(max_pv, max_sd)),
                 "qr_full": float((ok_pv & (full < max_sd)).mean() * 100) if len(grasps) else float("nan"),
                 "sd_same_as_run": float((grasps.sd.to_numpy(float) == full).mean()) if len(grasps) else float("nan")}
    perturbed = [(s, np.asarray(p, float)) for s, p in zip(metrics.sd, metrics.sd_perturbed)
                 if p is not None and len(p)] if "sd_perturbed" in metrics else []
    flips = [(p < max_sd) != (s < max_sd) for s, p in perturbed]
    out["robust_flips"] = float(np.concatenate(flips).mean()) if flips else None
    for n in counts:
        sd = sims["sd"][str(n)]
        before, after = full < max_sd, sd < max_sd
        out[str(n)] = {"qr": float((ok_pv & after).mean() * 100) if len(grasps) else float("nan"),
                       "flips": float((before != after).mean()) if len(grasps) else float("nan"),
                       "to_pass": int((after & ~before).sum()), "to_fail": int((before & ~after).sum()),
                       "net": int((after & ~before).sum() - (before & ~after).sum()),
                       "sd_abs_diff_median_cm": float(np.median(np.abs(sd - full)) * 100) if len(grasps) else None}
    out["ms_per_sim"] = {v: {"wall": float(sims["wall"][v].mean() * 1e3) if len(grasps) else None,
                             "cpu": float(sims["cpu"][v].mean() * 1e3) if len(grasps) else None} for v in sims["sd"]}
    out["ratio"] = {v: {k: float(sims[k][v].sum() / max(sims[k]["full"].sum(), 1e-12)) for k in ("wall", "cpu")}
                    for v in sims["sd"] if v != "full"}
    return out


def table_intervals(results: Path, table: str, labels: dict[str, str]) -> dict[tuple[str, str], tuple[float, float]]:
    """``(task, method) -> (qr_lo, qr_hi)`` from the run's ``results/tables/<table>.csv`` (none without it)."""
    path = results / "tables" / f"{table}.csv"
    if not path.is_file():
        return {}
    t = pd.read_csv(path)
    if not {"qr_lo", "qr_hi", "task", "method"} <= set(t.columns):
        return {}
    by_label = {label: m for m, label in labels.items()}
    return {(str(r.task), by_label[str(r.method)]): (float(r.qr_lo), float(r.qr_hi))
            for r in t.itertuples(index=False) if str(r.method) in by_label}


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--results", type=Path, default=Path("results"), help="a finished run's results folder")
    ap.add_argument("--counts", type=int, nargs="+", default=[1600, 800], help="collision hands' triangle counts")
    ap.add_argument("--methods", nargs="+", default=None,
                    help="default: the rows of --table that have a metric file")
    ap.add_argument("--tasks", nargs="+", default=None, help="default: the config's scenes.tasks")
    ap.add_argument("--table", default="table1")
    ap.add_argument("--limit", type=int, default=None, help="grasps per task and method (a seeded random subset)")
    ap.add_argument("--seed", type=int, default=0, help="the subset's seed")
    ap.add_argument("--configfile", type=Path, nargs="+", default=[REPO / "config" / "config.yaml"],
                    help="the run's config files, in the workflow's order")
    ap.add_argument("--cache-dir", type=Path, default=None, help="default: the config's cache_dir")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "sd_hand.json")
    a = ap.parse_args(argv)
    if a.limit is not None and a.limit < 1:
        ap.error("--limit must be at least 1")

    from tohgs.config import evaluation_sd_settings, load_configs
    from tohgs.hand import HandAssets
    from tohgs.hand.collision import MIN_TRIANGLES, collision_hand
    from tohgs.metrics.quality import SDSettings
    from tohgs.settings import settings_from

    cfg = load_configs(a.configfile, base_dir=REPO)
    tasks = a.tasks or list(cfg["scenes"]["tasks"])
    check_results(a.results, tasks)
    hand = HandAssets.load(a.results / "hand" / "hand.npz")
    bad = [n for n in a.counts if not MIN_TRIANGLES <= n < len(hand.closed_faces)]
    if bad:
        ap.error(f"--counts must lie in [{MIN_TRIANGLES}, {len(hand.closed_faces)}) for this hand, got {bad}")
    cache = a.cache_dir or Path(cfg["cache_dir"])
    variants = {"full": None, **{str(n): collision_hand(hand, n, cache) for n in a.counts}}
    settings = settings_from(SDSettings, evaluation_sd_settings(cfg))
    qr = cfg["evaluation"]["qr"]
    rows = a.methods or list(cfg["tables"][a.table]["rows"])
    labels = {m: cfg["methods"][m]["label"] for m in rows if m in cfg["methods"]}
    intervals = table_intervals(a.results, a.table, labels)
    report: dict = {"machine": platform.processor() or platform.machine(), "commit": commit_label(),
                    "results": str(a.results), "counts": a.counts, "limit": a.limit, "seed": a.seed,
                    "sd_settings": {**settings.__dict__}, "qr": qr,
                    "triangles": {v: (len(hand.closed_faces) if ch is None else ch.n_triangles)
                                  for v, ch in variants.items()},
                    "tasks": {}, "rows": {}}
    pooled: dict[str, list] = {}
    for task in tasks:
        report["tasks"][task] = {}
        for method in rows:
            if not (a.results / "metrics" / task / f"{method}.parquet").is_file():
                if a.methods:
                    raise SystemExit(f"{a.results}/metrics/{task}/{method}.parquet: no metric file of {method!r}")
                continue
            grasps, extra = grasps_of(a.results, task, method, a.limit, a.seed)
            t0 = time.perf_counter()
            sims = simulate(grasps, hand, variants, settings, a.results / "objects")
            entry = compare(grasps, extra["metrics"], sims, a.counts, qr["max_pv"], qr["max_sd"])
            if (task, method) in intervals:
                lo, hi = intervals[(task, method)]
                entry["qr_lo"], entry["qr_hi"] = lo, hi
                for n in a.counts:
                    entry[str(n)]["qr_in_interval"] = bool(lo <= entry[str(n)]["qr"] <= hi)
            report["tasks"][task][method] = entry
            pooled.setdefault(method, []).append((grasps, extra["metrics"], sims))
            each = [f"{n}: {entry[str(n)]['qr']:.1f} (flips {entry[str(n)]['flips']:.2f}, net {entry[str(n)]['net']:+d}, "
                    f"{entry['ratio'][str(n)]['cpu']:.2f}x)" for n in a.counts]
            print(f"{task}/{method}: {len(grasps)} grasps in {time.perf_counter() - t0:.0f} s; QR full "
                  f"{entry['qr_full']:.1f} {' '.join(each)}", flush=True)
    if not pooled:
        raise SystemExit(f"{a.results}: no metric file of {rows} for {tasks}")
    for method, parts in pooled.items():  # per row, the tasks pooled
        sims = {k: {v: np.concatenate([p[2][k][v] for p in parts]) for v in variants} for k in ("sd", "wall", "cpu")}
        report["rows"][method] = compare(pd.concat([p[0] for p in parts], ignore_index=True),
                                         pd.concat([p[1] for p in parts], ignore_index=True), sims, a.counts,
                                         qr["max_pv"], qr["max_sd"])
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(report, indent=1) + "\n")
    print(f"-> {a.out}")
    return report


if __name__ == "__main__":
    main(sys.argv[1:])
