"""The contact maps two rows' hands were made from, against those hands' PV and SD, on a finished run
(:mod:`tohgs.metrics.map_statistics`): for each task and pair of rows (``first:second``, e.g. a generator
on sampled maps and on ground-truth maps), the rows' mean map statistics, PV and SD, and the second row's
difference in PV and SD before and after the maps' statistics enter the regression, with intervals.

    python scripts/map_statistics.py --results results --out map_statistics.json
    python scripts/map_statistics.py --tasks placing --pairs ours:ours-gt-contact

Reads ``results/predictions/<task>/<row>.zarr``, ``results/metrics/<task>/<row>.parquet`` and the task's
test map shards; prints a Markdown table and writes the numbers as JSON with ``--out``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from tohgs.metrics.bootstrap import BootstrapSettings  # noqa: E402
from tohgs.metrics.map_statistics import STATISTICS, compare_rows, configuration_points, grasp_table  # noqa: E402

PAIRS = ["ours:ours-gt-contact", "m-grasptta-ta:m-grasptta-gt"]


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--results", default="results", help="the run's results folder")
    ap.add_argument("--tasks", nargs="+", default=["placing", "stacking", "shelving"])
    ap.add_argument("--pairs", nargs="+", default=PAIRS, help="first:second rows (method keys)")
    ap.add_argument("--samples", type=int, default=300, help="bootstrap resamples (0: no intervals)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=None, help="write the numbers here as JSON")
    args = ap.parse_args(argv)
    results = Path(args.results)
    boot = BootstrapSettings(samples=args.samples, seed=args.seed)
    out: dict = {}
    lines = ["| task | rows | mean c² | share above 0.9 | offset (cm) | PV (cm³) | SD (cm) | outcome | second - first | "
             "given the maps | per SD of " + " / ".join(STATISTICS) + " |", "|" + "---|" * 11]
    fmt = lambda c: f"{c['value']:+.2f} [{c['lo']:+.2f}, {c['hi']:+.2f}]"  # noqa: E731
    for task in args.tasks:
        shards = sorted((results / "maps" / task / "test").glob("shard-*.zarr"))
        if not shards:
            raise SystemExit(f"{results / 'maps' / task / 'test'}: no map shards (is this a finished run's results?)")
        points = configuration_points(shards)
        for pair in args.pairs:
            first, _, second = pair.partition(":")
            if not second:
                raise SystemExit(f"--pairs: {pair!r} is not first:second")
            rows = [grasp_table(results / "predictions" / task / f"{m}.zarr", results / "metrics" / task / f"{m}.parquet",
                                points) for m in (first, second)]
            entry = {y: compare_rows(*rows, y, boot) for y in ("pv", "sd")}
            out.setdefault(task, {})[pair] = entry
            means = entry["pv"]["means"]
            cols = " | ".join(f"{means['first'][k]:.3f} / {means['second'][k]:.3f}"
                              for k in (*STATISTICS, "pv", "sd"))
            for y in ("pv", "sd"):
                per = " / ".join(fmt(entry[y][s]) for s in STATISTICS)
                lines.append(f"| {task} | {pair} | {cols} | {y} | {fmt(entry[y]['row_alone'])} | "
                             f"{fmt(entry[y]['row_given_maps'])} | {per} |")
    print("\n".join(lines))
    if args.out:
        Path(args.out).write_text(json.dumps(out, indent=1) + "\n")
    return out


if __name__ == "__main__":
    main()
