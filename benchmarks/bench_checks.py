"""What the read checks cost in an evaluation job: the cache entries' checksums (:mod:`tohgs.cache`) and the
object folders' recorded names (:func:`tohgs.assets.manifest.check_meta_name`), as a share of the job.

Runs the evaluation of one task and method of a finished run (``results/predictions/<task>/<method>.zarr``) as
its job does (:func:`tohgs.metrics.evaluate.evaluate_predictions`, the config's SD protocol), in this process
with its per-process caches emptied first (a job's process starts with none), and times every call of the
checks inside it: the share is their summed time over the job's, so a busy machine scales both alike. A cache
entry without a checksum (written before the checks) is recomputed once and gets one: the first of
``--repeats`` runs warms the cache and is not counted.

    python benchmarks/bench_checks.py --results results --task placing --method ours [--repeats 3] \\
        [--out benchmarks/results/checks.json]
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", default="results", help="a finished run's results folder")
    ap.add_argument("--task", default="placing")
    ap.add_argument("--method", default="ours")
    ap.add_argument("--repeats", type=int, default=3, help="runs; the first warms the cache and is not counted")
    ap.add_argument("--configfile", default=str(REPO / "config" / "config.yaml"))
    ap.add_argument("--out", default=None)
    args = ap.parse_args()

    import tohgs.assets.manifest as manifest
    import tohgs.cache as cache
    import tohgs.io as tio
    from base_commit import cpu_name
    from evaluation_job import evaluate_as_job
    from tohgs.config import load_config

    cfg = load_config(args.configfile)
    spent = {"verified": 0.0, "check_meta_name": 0.0}
    calls = {"verified": 0, "check_meta_name": 0}

    def timed(name, fn):
        def wrapper(*a, **k):
            t0 = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                spent[name] += time.perf_counter() - t0
                calls[name] += 1
        return wrapper

    cache.verified = timed("verified", cache.verified)
    manifest.check_meta_name = timed("check_meta_name", manifest.check_meta_name)
    runs = []
    for r in range(args.repeats):
        tio._DIGESTS.clear()
        manifest._METAS.clear()
        for k in spent:
            spent[k], calls[k] = 0.0, 0
        t0 = time.perf_counter()
        rows = evaluate_as_job(cfg, args.results, args.task, args.method)
        total = time.perf_counter() - t0
        run = {"job_s": round(total, 3), "grasps": len(rows), **{f"{k}_s": round(v, 5) for k, v in spent.items()},
               **{f"{k}_calls": n for k, n in calls.items()}, "share": sum(spent.values()) / total}
        print(json.dumps(run), flush=True)
        if r > 0 or args.repeats == 1:
            runs.append(run)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True).stdout.strip()
    out = {"benchmark": "bench_checks", "commit": commit, "machine": platform.machine(), "cpu": cpu_name(),
           "task": args.task, "method": args.method, "runs": runs,
           "share_max": max(r["share"] for r in runs), "share_mean": sum(r["share"] for r in runs) / len(runs)}
    print(json.dumps({k: v for k, v in out.items() if k != "runs"}))
    if args.out:
        from tohgs.io import write_json

        write_json(args.out, out)


if __name__ == "__main__":
    main()
