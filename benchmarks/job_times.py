"""The job time of a finished workflow run, per stage and per rule, and what a stage costs per object and
per test configuration (to size a run): read from Snakemake's ``benchmark:`` files
(``results/benchmarks/**/*.tsv``, the first column: a job's wall seconds) and the run's metric files.

    python benchmarks/job_times.py results/ [--out benchmarks/results/job_times.json]

Stages are the benchmark folders of the heavy rules (``objects``, ``scenes``, ``grasps/prior_synthesis``,
``maps``, ``models``, ``predictions``, ``metrics``); ``models``, ``predictions`` and ``metrics`` are also
split by component or method (the file's stem). Per object: the objects and prior-grasp stages; per task
and object: the scenes; per test configuration: predictions and metrics over the test configurations of
every task (counted from ``results/metrics``).
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
from collections import defaultdict
from pathlib import Path

import pandas as pd


def job_seconds(tsv: Path) -> float:
    """The wall seconds of one job's benchmark file (Snakemake's ``s`` column, the last line)."""
    frame = pd.read_csv(tsv, sep="\t")
    return float(frame["s"].iloc[-1])


def job_times(results: Path) -> dict:
    """Per stage: jobs and minutes; per component or method: minutes; per object and per test
    configuration: seconds (module docstring)."""
    root = results / "benchmarks"
    if not root.is_dir():
        raise SystemExit(f"{root}: no benchmark files (is {results} the results folder of a finished run?)")
    stages: dict[str, list[float]] = defaultdict(list)
    parts: dict[str, dict[str, float]] = defaultdict(lambda: defaultdict(float))
    for tsv in sorted(root.rglob("*.tsv")):
        rel = tsv.relative_to(root).parts
        stage = "/".join(rel[:2]) if rel[0] == "grasps" else rel[0]
        seconds = job_seconds(tsv)
        stages[stage].append(seconds)
        if rel[0] in ("models", "predictions", "metrics"):
            parts[rel[0]][tsv.stem] += seconds / 60
    out: dict = {"stages": {k: {"jobs": len(v), "minutes": round(sum(v) / 60, 2)} for k, v in sorted(stages.items())},
                 "by_part": {k: {n: round(m, 2) for n, m in sorted(v.items(), key=lambda kv: -kv[1])}
                             for k, v in parts.items()}}
    out["total_minutes"] = round(sum(sum(v) for v in stages.values()) / 60, 2)
    configs = 0
    for parquet in (results / "metrics").glob("*/dataset.parquet"):
        rows = pd.read_parquet(parquet, columns=["object", "config_index"])
        configs += len(rows.drop_duplicates())
    objects = len(stages.get("objects", []))
    per = {}
    if objects:
        per["objects_s_per_object"] = round(sum(stages["objects"]) / objects, 1)
        for stage in ("grasps/prior_synthesis",):
            if stage in stages:
                per["prior_synthesis_s_per_object"] = round(sum(stages[stage]) / len(stages[stage]), 1)
    if "scenes" in stages:
        per["scenes_s_per_task_object"] = round(sum(stages["scenes"]) / len(stages["scenes"]), 1)
    if configs:
        for stage in ("predictions", "metrics"):
            if stage in stages:
                per[f"{stage}_s_per_test_config"] = round(sum(stages[stage]) / configs, 1)
        out["test_configs"] = configs
    out["per_unit"] = per
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results", type=Path, help="the results folder of a finished run")
    ap.add_argument("--out", type=Path, help="write the JSON here too")
    args = ap.parse_args()
    report = job_times(args.results)
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                cwd=args.results.parent).stdout.strip()
    except OSError:
        commit = ""
    report = {"benchmark": "job_times", "machine": platform.machine(), "commit": commit, **report}
    text = json.dumps(report, indent=2)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
