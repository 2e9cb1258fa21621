"""Does a trained method fit its training configurations better than its test ones? On a finished run.

A method's test predictions and metrics are the run's (``results/predictions/<task>/<method>.zarr``,
``results/metrics/<task>/<method>.parquet``); this predicts the same method, with the settings its test
store records, on one training shard of the task (``results/maps/<task>/train/shard-<k>.zarr``: every
configuration of it) and evaluates those grasps as the evaluation stage does (the config's SD, PV and hand
settings, the task's scene stores), then compares the two per task: grasps, QR (PV < ``evaluation.qr.max_pv``
and SD < ``max_sd``, %), the share failing SD, PV avg (cm^3), Init and Goal OPP (%), and TS. For
``ours-gt-contact`` (the GraspDiffuser on the configuration's own ground-truth maps) a training score well
above the test score says the network memorises its data; a training score no higher says it does not
reproduce even the grasps it was trained on (docs/history.md, issue 50).

    python benchmarks/train_fit.py --results results --tasks placing shelving [--method ours-gt-contact] \\
        [--shard 0] [--configfile config/config.yaml] [--out benchmarks/results/train_fit.json]

About 7 minutes a task on one core of a 2-core machine (112 training configurations of 16 grasps, the
GraspDiffuser sampled by DDPM 1000). The training predictions and metrics are kept under
``<results>/train_fit/`` and reused by a second call.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from base_commit import commit_label, cpu_name  # noqa: E402

from tohgs.config import evaluation_sd_settings, load_configs, run_cache_dir  # noqa: E402
from tohgs.data.predictions import read_predictions  # noqa: E402
from tohgs.hand import HandAssets  # noqa: E402
from tohgs.io import atomic_path, write_json  # noqa: E402
from tohgs.metrics.evaluate import evaluate_predictions  # noqa: E402
from tohgs.metrics.quality_thresholds import QualityThresholds  # noqa: E402
from tohgs.metrics.tables import summarize  # noqa: E402
from tohgs.methods import method_components  # noqa: E402
from tohgs.methods.predict import predict  # noqa: E402


def summary(rows: pd.DataFrame, t: QualityThresholds) -> dict[str, float]:
    """The table's numbers of one set of evaluated grasps (:func:`tohgs.metrics.tables.summarize`, of its
    kept ones: grasps, QR %, PV avg cm^3, Init / Goal OPP %, TS) and the share of them failing SD, %."""
    row = summarize(rows, t)
    kept = rows[rows.kept]
    return {**{k: row[k] for k in ("grasps", "qr", "pv_avg", "init_opp", "goal_opp", "ts")},
            "sd_fail": 100 * float((~(kept.sd < t.max_sd)).mean())}


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", type=Path, default=Path("results"), help="the run's results folder")
    ap.add_argument("--tasks", nargs="+", default=["placing"])
    ap.add_argument("--method", default="ours-gt-contact")
    ap.add_argument("--shard", type=int, default=0, help="which training shard of the task")
    ap.add_argument("--configfile", nargs="+", default=[str(REPO / "config/config.yaml")],
                    help="the run's config files (SD, PV and the method's block)")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks/results/train_fit.json")
    a = ap.parse_args(argv)
    run = a.results.resolve().parent
    cfg = load_configs(a.configfile, base_dir=run)
    t = QualityThresholds(**cfg["evaluation"]["qr"])
    method = cfg["methods"][a.method]
    hand = a.results / "hand/hand.npz"
    out: dict = {"method": a.method, "shard": a.shard, "commit": commit_label(), "cpu": cpu_name(),
                 "configfile": a.configfile, "tasks": {}}
    for task in a.tasks:
        test_store = a.results / f"predictions/{task}/{a.method}.zarr"
        test_metrics = a.results / f"metrics/{task}/{a.method}.parquet"
        for path in (test_store, test_metrics):
            if not path.exists():
                raise SystemExit(f"{path}: missing (run the workflow's {a.method} row for {task} first)")
        _, attrs = read_predictions(test_store)
        work = a.results / "train_fit" / task
        work.mkdir(parents=True, exist_ok=True)
        store, metrics = work / f"{a.method}.zarr", work / f"{a.method}.parquet"
        if not store.exists():
            components = method_components(method, cfg["components"])
            predict(task, a.method, method, [a.results / f"maps/{task}/train/shard-{a.shard}.zarr"],
                    {c: a.results / f"models/{task}/{c}.pt" for c in components}, dict(attrs["config"]), store,
                    hand=hand, complete=True)
        if not metrics.exists():
            ev = cfg["evaluation"]
            rows = evaluate_predictions(store, sorted((a.results / f"scenes/{task}").glob("*.zarr")),
                                        a.results / "objects", a.results / "objects/supports/supports.json",
                                        HandAssets.load(hand), evaluation_sd_settings(cfg), cfg["metrics"]["voxel_pitch"],
                                        run_cache_dir(cfg, run), progress=True, pv_mesh=ev["pv_mesh"],
                                        sd_hand=ev["sd_hand"])
            with atomic_path(metrics) as tmp:  # a killed call leaves no partial file for the next to reuse
                rows.to_parquet(tmp, index=False)
        out["tasks"][task] = {"train": summary(pd.read_parquet(metrics), t),
                              "test": summary(pd.read_parquet(test_metrics), t)}
        for split, s in out["tasks"][task].items():
            print(f"{task} {split:5s} " + " ".join(f"{k} {v:.3f}" for k, v in s.items()))
    write_json(a.out, out)
    return out


if __name__ == "__main__":
    main()
