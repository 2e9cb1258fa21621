"""Does SD come out the same under another Python's pybullet? (pybullet 3.2.7 has PyPI wheels up to CPython
3.11; for 3.12 and 3.13 ``make setup`` builds one from the sdist: ``scripts/pybullet_wheel.sh``.)

Run once per interpreter (each its own venv of this checkout) on the same finished run's grasps; each run
evaluates one task and method as its job does (:func:`tohgs.metrics.evaluate.evaluate_predictions`, the
config's SD protocol) and writes every grasp's SD with the interpreter's and pybullet's versions; then compare:

    .venv/bin/python benchmarks/sd_interpreters.py run --results results --out /tmp/sd-311.json
    .venv312/bin/python benchmarks/sd_interpreters.py run --results results --out /tmp/sd-312.json
    python benchmarks/sd_interpreters.py compare /tmp/sd-311.json /tmp/sd-312.json [--out benchmarks/results/sd_interpreters.json]

``compare`` reports how many SDs are bit-identical, the largest difference (m) and how many SD < 2 cm verdicts
differ. Same machine only: across CPUs the simulation itself differs in the last bits.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))


def run(args: argparse.Namespace) -> None:
    import numpy as np
    import pybullet

    from evaluation_job import evaluate_as_job
    from tohgs.config import load_config
    from tohgs.io import write_json

    results = Path(args.results)
    rows = evaluate_as_job(load_config(args.configfile), results, args.task, args.method)
    sd_values = np.asarray(rows["sd"], dtype=np.float64)
    write_json(args.out, {"python": platform.python_version(), "pybullet_numpy": int(pybullet.isNumpyEnabled()),
                          "task": args.task, "method": args.method, "results": str(results),
                          "sd": [float(v) for v in sd_values]})
    print(f"{len(sd_values)} SDs with Python {platform.python_version()} -> {args.out}")


def compare(args: argparse.Namespace) -> None:
    import numpy as np

    a, b = (json.loads(Path(p).read_text()) for p in (args.a, args.b))
    x, y = np.asarray(a["sd"], dtype=np.float64), np.asarray(b["sd"], dtype=np.float64)
    if x.shape != y.shape:
        raise SystemExit(f"{args.a} has {len(x)} SDs, {args.b} {len(y)}: not the same grasps")
    same = (x == y) | (np.isnan(x) & np.isnan(y))
    diff = np.abs(x - y)[~same]
    out = {"benchmark": "sd_interpreters", "a": a["python"], "b": b["python"], "task": a["task"], "method": a["method"],
           "grasps": int(len(x)), "bit_identical": int(same.sum()),
           "max_abs_diff_m": float(diff.max()) if len(diff) else 0.0,
           "verdicts_differ": int(((x < args.max_sd) != (y < args.max_sd)).sum()),
           "pybullet_numpy": [a["pybullet_numpy"], b["pybullet_numpy"]]}
    print(json.dumps(out))
    if args.out:
        sys.path.insert(0, str(REPO))
        from tohgs.io import write_json

        write_json(args.out, out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="evaluate one task and method, write the SDs")
    r.add_argument("--results", default="results")
    r.add_argument("--task", default="placing")
    r.add_argument("--method", default="ours")
    r.add_argument("--configfile", default=str(REPO / "config" / "config.yaml"))
    r.add_argument("--out", required=True)
    c = sub.add_parser("compare", help="compare two runs' SDs")
    c.add_argument("a")
    c.add_argument("b")
    c.add_argument("--max-sd", type=float, default=0.02, help="QR's SD threshold, m")
    c.add_argument("--out", default=None)
    args = ap.parse_args()
    run(args) if args.cmd == "run" else compare(args)


if __name__ == "__main__":
    main()
