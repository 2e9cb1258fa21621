"""Every method's cost in a finished run: seconds per grasp of each prediction stage (the prediction
stores' ``timing``, measured inside the prediction jobs, one torch thread each) and the training seconds
of each component (the checkpoints' ``seconds``), per task, from a results folder.

Not a timing of its own: it gathers what the workflow measured, so that every method of a run is
compared on the same machine, under the same load. Writes ``benchmarks/results/methods.json`` (or
``--out``); run it after ``make reproduce`` (``--results`` names another run's folder).
"""

from __future__ import annotations

import argparse
import json
import platform
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def gather(results: Path) -> dict:
    """Per task: ``methods`` (seconds per grasp per stage and in all, grasps, configurations) and
    ``components`` (training seconds and steps)."""
    from tohgs.data.predictions import read_predictions

    out: dict = {}
    for store in sorted(results.glob("predictions/*/*.zarr")):
        task, method = store.parent.name, store.stem
        arrays, attrs = read_predictions(store)
        timing = {k.removeprefix("seconds_per_"): round(float(v), 5) for k, v in attrs.get("timing", {}).items()}
        out.setdefault(task, {"methods": {}, "components": {}})["methods"][method] = {
            "seconds_per_grasp": round(sum(timing.values()), 5), "stages": timing,
            "grasps": int(arrays["kept"].size), "configurations": int(len(arrays["object_id"])),
            "method_of": attrs.get("method_config", {}).get("of")}
    from tohgs.models.checkpoint import load_checkpoint

    for ckpt in sorted(results.glob("models/*/*.pt")):
        meta = load_checkpoint(ckpt)
        task, comp = ckpt.parent.name, ckpt.stem
        out.setdefault(task, {"methods": {}, "components": {}})["components"][comp] = {
            "kind": meta.get("kind"), "training_seconds": round(float(meta.get("seconds") or 0.0), 1),
            "steps": (meta.get("training_config") or {}).get("steps")}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--results", default=str(REPO / "results"))
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "methods.json"))
    args = ap.parse_args()
    results = Path(args.results)
    if not results.is_dir():
        raise SystemExit(f"{results}: no results folder (run the workflow first)")
    data = {"benchmark": "methods", "machine": platform.processor() or platform.machine(),
            "source": "prediction stores' timing and checkpoints' training seconds of one run", "tasks": gather(results)}
    Path(args.out).write_text(json.dumps(data, indent=2) + "\n")
    for task, block in data["tasks"].items():
        for m, v in block["methods"].items():
            print(f"{task:9s} {m:18s} {v['seconds_per_grasp']:8.4f} s/grasp  {v['stages']}")


if __name__ == "__main__":
    main()
