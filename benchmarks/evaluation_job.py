"""One evaluation job of a finished run, run in this process as the workflow's rule ``evaluate`` runs it: the
benchmarks that time or compare what it does (bench_checks.py, sd_interpreters.py) share it."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import pandas as pd

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))


def evaluate_as_job(cfg: dict[str, Any], results: str | Path, task: str, method: str) -> pd.DataFrame:
    """The metric rows of ``results/predictions/<task>/<method>.zarr`` with the config's SD protocol
    (:func:`tohgs.config.evaluation_sd_settings`, as the workflow passes it), voxel pitch, PV mesh, SD hand and
    cache (:func:`tohgs.config.run_cache_dir`: relative to the run's folder) of ``cfg``, a validated config
    (:func:`tohgs.config.load_configs`)."""
    from tohgs.config import evaluation_sd_settings, run_cache_dir
    from tohgs.hand import HandAssets
    from tohgs.metrics.evaluate import evaluate_predictions

    results = Path(results)
    sd = evaluation_sd_settings(cfg)
    return evaluate_predictions(results / "predictions" / task / f"{method}.zarr",
                                sorted((results / "scenes" / task).glob("*.zarr")), results / "objects",
                                results / "objects" / "supports" / "supports.json",
                                HandAssets.load(results / "hand" / "hand.npz"), sd, cfg["metrics"]["voxel_pitch"],
                                run_cache_dir(cfg, results.parent),
                                sd_hand=cfg["evaluation"]["sd_hand"], pv_mesh=cfg["evaluation"]["pv_mesh"])
