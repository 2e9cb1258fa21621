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
    (``metrics.sd`` with ``evaluation.sd_gravity``'s direction and vector, as ``workflow/rules/common.smk``'s
    ``evaluation_sd_settings`` passes it: :func:`tohgs.config.evaluation_sd_settings`), voxel pitch, PV mesh, SD hand and cache (relative to the run's folder)
    of ``cfg``, a validated config (:func:`tohgs.config.load_config`)."""
    from tohgs.config import evaluation_sd_settings
    from tohgs.hand import HandAssets
    from tohgs.metrics.evaluate import evaluate_predictions

    results = Path(results)
    sd = evaluation_sd_settings(cfg)
    cache = Path(cfg["cache_dir"])
    return evaluate_predictions(results / "predictions" / task / f"{method}.zarr",
                                sorted((results / "scenes" / task).glob("*.zarr")), results / "objects",
                                results / "objects" / "supports" / "supports.json",
                                HandAssets.load(results / "hand" / "hand.npz"), sd, cfg["metrics"]["voxel_pitch"],
                                cache if cache.is_absolute() else results.parent / cache,
                                sd_hand=cfg["evaluation"]["sd_hand"], pv_mesh=cfg["evaluation"]["pv_mesh"])
