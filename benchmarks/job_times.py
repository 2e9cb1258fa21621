"""The job time of a finished workflow run, per stage and per rule, and what a stage costs per object and
per test configuration (to size a run): read from Snakemake's ``benchmark:`` files
(``results/benchmarks/**/*.tsv``, the first column: a job's wall seconds) and the run's metric files.

    python benchmarks/job_times.py results/ [--log reproduce.log --cores 2] [--out benchmarks/results/job_times.json]

Stages are the benchmark folders of the heavy rules (``objects``, ``scenes``, ``grasps/prior_synthesis``,
``maps``, ``models``, ``predictions``, ``metrics``); ``models``, ``predictions`` and ``metrics`` are also
split by component or method (the file's stem). Per object: the objects and prior-grasp stages; per task
and object: the scenes; per test configuration: predictions and metrics over the test configurations of
every task (counted from ``results/metrics``). With ``--log``, the run's Snakemake log (what ``make reproduce``
prints) gives each job's start and finish: the run's span, the core-minutes its jobs held (their threads) and
how many of the ``--cores`` stood idle, so that a wall clock can be read against the job time.
"""

from __future__ import annotations

import argparse
import json
import platform
import re
import subprocess
import sys
from collections import defaultdict
from datetime import datetime
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
from base_commit import cpu_name  # noqa: E402


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


_STAMP = re.compile(r"^\[(\w{3} \w{3} +\d+ \d\d:\d\d:\d\d \d{4})\]$")
_RULE = re.compile(r"^(?:local)?rule (\w+):$")
_FINISHED = re.compile(r"^Finished jobid: (\d+)")


def log_jobs(log: Path) -> list[dict]:
    """The jobs of a Snakemake log (one run, or several appended): per job its rule, threads, start and
    finish (datetimes, to the second; a job the log never finishes is left out). A job is announced by a
    time stamp line, ``rule <name>:`` (or ``localrule``) and indented ``jobid:`` / ``threads:`` lines, and
    ends at ``Finished jobid: <id>``; ids restart with each run, so a finish closes the latest job of its id."""
    jobs: list[dict] = []
    open_by_id: dict[int, dict] = {}
    stamp: datetime | None = None
    current: dict | None = None
    for line in log.read_text(errors="replace").splitlines():
        m = _STAMP.match(line)
        if m:
            stamp = datetime.strptime(" ".join(m.group(1).split()), "%a %b %d %H:%M:%S %Y")
            current = None
            continue
        m = _RULE.match(line)
        if m and stamp is not None:
            current = {"rule": m.group(1), "threads": 1, "start": stamp}
            continue
        if current is not None and line.startswith("    "):
            key, _, value = line.strip().partition(": ")
            if key == "jobid":
                current["id"] = int(value)
                open_by_id[current["id"]] = current
                jobs.append(current)
            elif key == "threads":
                current["threads"] = int(value)
            continue
        current = None
        m = _FINISHED.match(line)
        if m and stamp is not None and int(m.group(1)) in open_by_id:
            open_by_id.pop(int(m.group(1)))["end"] = stamp
    return [j for j in jobs if "end" in j]


def core_use(jobs: list[dict], cores: int) -> dict:
    """The span of the ``jobs`` (:func:`log_jobs`) from the first start to the last finish, the core-minutes
    they held (wall time x threads) and the core-minutes of ``cores`` that no job held (minute by minute,
    a minute's use capped at ``cores``)."""
    if not jobs:
        raise SystemExit("the log holds no finished job")
    t0, t1 = min(j["start"] for j in jobs), max(j["end"] for j in jobs)
    minutes = int((t1 - t0).total_seconds() // 60) + 1
    use = [0.0] * minutes
    for j in jobs:
        a, b = (j["start"] - t0).total_seconds(), (j["end"] - t0).total_seconds()
        for k in range(int(a // 60), int(b // 60) + 1):
            overlap = min(b, (k + 1) * 60) - max(a, k * 60)
            if overlap > 0:
                use[k] += overlap / 60 * j["threads"]
    span = (t1 - t0).total_seconds() / 60
    held = sum((j["end"] - j["start"]).total_seconds() * j["threads"] for j in jobs) / 60
    return {"jobs": len(jobs), "span_minutes": round(span, 1), "cores": cores, "core_minutes_held": round(held, 1),
            "core_minutes_idle": round(cores * span - sum(min(u, cores) for u in use), 1)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results", type=Path, help="the results folder of a finished run")
    ap.add_argument("--out", type=Path, help="write the JSON here too")
    ap.add_argument("--log", type=Path, help="the run's Snakemake log: the span and the idle cores too")
    ap.add_argument("--cores", type=int, default=2, help="the run's --cores (with --log)")
    args = ap.parse_args()
    report = job_times(args.results)
    if args.log:
        report["log"] = core_use(log_jobs(args.log), args.cores)
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                cwd=args.results.parent).stdout.strip()
    except OSError:
        commit = ""
    report = {"benchmark": "job_times", "machine": platform.machine(), "cpu": cpu_name(), "commit": commit, **report}
    text = json.dumps(report, indent=2)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
