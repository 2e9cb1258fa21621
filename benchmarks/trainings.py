"""Two rows over several trainings: is one above the other, or is that one training's draw? On a finished run.

A row's seed replicas (config key ``seeds``: ``<method>`` for the first seed, ``<method>-seed<s>`` for each
other, every network retrained and resampled with its seed) are read from ``<results>/metrics/<task>/``
and pooled as the tables pool them (:func:`tohgs.metrics.tables.read_metrics`). Per task:

- each row pooled: TS, QR, PV avg, Init and Goal OPP, TS's 95 % interval (hierarchical bootstrap over test
  objects, then configurations) and its standard deviation across the trainings;
- each training alone: TS and the half-width of its interval (the same resamples);
- the claim "``--better`` beats ``--than``" on the pooled rows, by the claims table's own tests
  (:func:`tohgs.metrics.claims.claim_rows`): the difference, its paired bootstrap interval, the per-object
  sign-flip test, and how many test objects would tell it.

Written for issue 50's "Ours (GT contact) >= Ours on every task": one training's sign of that difference is
a draw when the difference is smaller than the training-to-training spread (docs/history.md).

    python benchmarks/trainings.py --results results --tasks placing stacking shelving \\
        [--better ours-gt-contact] [--than ours] [--seeds 0 1 2] [--configfile config/config.yaml] \\
        [--out benchmarks/results/trainings.json]

Seconds: it reads metric files only. A missing replica's file is named in the error (run
``snakemake --configfile config/config.yaml <a file with seeds: [0, 1, 2]> <its metric files>`` first).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from base_commit import commit_label, cpu_name  # noqa: E402

from tohgs.config import load_configs, replica_name  # noqa: E402
from tohgs.io import write_json  # noqa: E402
from tohgs.metrics.bootstrap import BootstrapSettings, cells, config_keys, config_stats, resample_weights  # noqa: E402
from tohgs.metrics.claims import claim_rows  # noqa: E402
from tohgs.metrics.quality_thresholds import QualityThresholds  # noqa: E402
from tohgs.metrics.tables import metric_table, read_metrics  # noqa: E402

COLUMNS = ["ts", "qr", "pv_avg", "init_opp", "goal_opp"]


def compare(results: Path, tasks: list[str], better: str, than: str, seeds: list[int],
            t: QualityThresholds, bootstrap: BootstrapSettings) -> dict:
    """Per task, both rows pooled over ``seeds``, each training alone and the claim (module docstring)."""
    replicas = {m: {replica_name(m, seeds, s): s for s in seeds} for m in (better, than)}
    paths = [results / f"metrics/{task}/{name}.parquet" for task in tasks for reps in replicas.values()
             for name in reps]
    missing = [str(p) for p in paths if not p.exists()]
    if missing:
        raise SystemExit(f"{', '.join(missing)}: missing (evaluate every replica of seeds {seeds} first)")
    rows = read_metrics(paths, replicas)
    pooled = metric_table(rows, tasks, [than, better], {}, COLUMNS, t, bootstrap=bootstrap)
    claim = {"text": f"{better} beats {than}", "table": "pooled", "better": better, "than": [than]}
    verdicts = pd.DataFrame(claim_rows(rows, "pooled", claim, [than, better], {}, t, bootstrap, tasks))
    tail = (1 - bootstrap.level) / 2 * 100
    out = {}
    for ti, task in enumerate(tasks):
        in_task = rows[rows.task == task]
        keys = config_keys(in_task)
        weights = resample_weights(keys.object.to_numpy(), bootstrap.samples,
                                   np.random.default_rng([bootstrap.seed, ti]))
        one = np.ones((1, len(keys)))
        per_training = {}
        for m in (than, better):
            for s in seeds:
                sel = in_task[(in_task.method == m) & (in_task.seed == s)]
                stats = config_stats(sel, keys, t.max_pv, t.max_sd)
                lo, hi = np.percentile(cells(weights, stats)["ts"], [tail, 100 - tail])
                per_training[replica_name(m, seeds, s)] = {
                    "ts": float(cells(one, stats)["ts"][0]), "ts_half_width": float((hi - lo) / 2)}
        table = pooled[pooled.task == task].set_index("method")
        row = verdicts[verdicts.task == task].iloc[0]
        out[task] = {
            "pooled": {m: {c: float(table.loc[m, c]) for c in table.columns if c != "task"} for m in (than, better)},
            "per_training": per_training,
            "difference": float(row.difference), "lo": float(row.lo), "hi": float(row.hi),
            "verdict": row.verdict, "objects": int(row.objects), "objects_favour": int(row.objects_favour),
            "p_objects": float(row.p_objects), "paired_verdict": row.paired_verdict,
            "objects_needed": float(row.objects_needed)}
    return out


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", type=Path, default=Path("results"), help="the run's results folder")
    ap.add_argument("--tasks", nargs="+", default=["placing", "stacking", "shelving"])
    ap.add_argument("--better", default="ours-gt-contact", help="the row claimed to be better")
    ap.add_argument("--than", default="ours", help="the row it is claimed to beat")
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2], help="the run's config key seeds")
    ap.add_argument("--configfile", nargs="+", default=[str(REPO / "config/config.yaml")],
                    help="the run's config files (QR thresholds, the tables' bootstrap settings)")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks/results/trainings.json")
    a = ap.parse_args(argv)
    if len(a.seeds) < 2 or len(set(a.seeds)) != len(a.seeds):
        raise SystemExit(f"--seeds {a.seeds}: give two or more distinct seeds")
    cfg = load_configs(a.configfile, base_dir=a.results.resolve().parent)
    bootstrap = BootstrapSettings(**cfg["evaluation"]["bootstrap"])
    tasks = compare(a.results, a.tasks, a.better, a.than, a.seeds, QualityThresholds(**cfg["evaluation"]["qr"]),
                    bootstrap)
    out = {"benchmark": "trainings", "commit": commit_label(), "cpu": cpu_name(), "results": str(a.results),
           "configfile": a.configfile, "better": a.better, "than": a.than, "seeds": a.seeds,
           "bootstrap": {"samples": bootstrap.samples, "level": bootstrap.level, "seed": bootstrap.seed},
           "tasks": tasks}
    for task, r in tasks.items():
        trainings = ", ".join(f"{k} {v['ts']:.3f}" for k, v in r["per_training"].items())
        print(f"{task}: {a.better} - {a.than} pooled {r['difference']:+.3f} [{r['lo']:+.3f}, {r['hi']:+.3f}] "
              f"({r['verdict']}; per object {r['objects_favour']}/{r['objects']}, p {r['p_objects']:.2f}); "
              f"trainings: {trainings}")
    write_json(a.out, out)
    return out


if __name__ == "__main__":
    main()
