"""benchmarks/trainings.py: two rows pooled over their trainings (seed replicas), each training alone, and the
claim that one beats the other by the claims table's tests."""

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from helpers import load_benchmark
from tohgs.metrics.evaluate import COLUMNS

trainings = load_benchmark("trainings")


def _rows(method: str, p_good: np.ndarray, rng: np.random.Generator, objects: int = 12, configs: int = 2,
          grasps: int = 16) -> pd.DataFrame:
    """Metric rows of ``objects`` test objects whose grasps hold with probability ``p_good`` (per object)."""
    o, c, g = np.meshgrid(np.arange(objects), np.arange(configs), np.arange(grasps), indexing="ij")
    good = rng.random(o.shape) < p_good[:, None, None]
    n = good.size
    return pd.DataFrame({"task": "placing", "method": method, "object": np.char.add("o", o.ravel().astype(str)),
                         "config_index": c.ravel(), "sample": g.ravel(), "pv": 1e-6,
                         "sd": np.where(good.ravel(), 0.01, 0.05), "contact_distance": 0.0, "init_opp": 0.0,
                         "goal_opp": 0.0, "ds": 0.1, "hand_vertices": 778, "kept": True,
                         "sd_perturbed": [[] for _ in range(n)], "sd_palm": np.nan})[list(COLUMNS)]


def _run(tmp_path: Path, lead: float) -> dict:
    """Three trainings of ``a`` and ``b`` on 12 objects, ``b`` holding ``lead`` more often on every object."""
    rng = np.random.default_rng(0)
    base = rng.uniform(0.3, 0.6, 12)
    folder = tmp_path / "results/metrics/placing"
    folder.mkdir(parents=True)
    for seed in (0, 1, 2):
        for method, shift in (("a", 0.0), ("b", lead)):
            name = method if seed == 0 else f"{method}-seed{seed}"
            _rows(name, np.clip(base + shift + 0.03 * seed, 0, 1), rng).to_parquet(folder / f"{name}.parquet")
    out = tmp_path / "trainings.json"
    trainings.main(["--results", str(tmp_path / "results"), "--tasks", "placing", "--better", "b", "--than", "a",
                    "--out", str(out)])
    return json.loads(out.read_text())["tasks"]["placing"]


def test_a_row_ahead_on_every_object_is_told_and_every_training_is_reported(tmp_path):
    r = _run(tmp_path, lead=0.3)
    assert set(r["per_training"]) == {"a", "a-seed1", "a-seed2", "b", "b-seed1", "b-seed2"}
    pooled_b = np.mean([r["per_training"][k]["ts"] for k in ("b", "b-seed1", "b-seed2")])
    assert r["pooled"]["b"]["ts"] == pytest.approx(pooled_b, abs=1e-9)  # equal grasp counts: the mean
    assert r["difference"] > 0.2 and r["lo"] > 0 and r["verdict"] == "holds"
    assert r["objects_favour"] == 12 and r["p_objects"] < 0.01 and r["paired_verdict"] == "holds"
    assert r["pooled"]["b"]["ts_seed_sd"] > 0  # the trainings differ (by 0.03 a seed)


def test_two_rows_alike_cannot_be_told_apart(tmp_path):
    r = _run(tmp_path, lead=0.0)
    assert abs(r["difference"]) < 0.05 and r["lo"] < 0 < r["hi"] and r["verdict"] == "cannot tell"


def test_a_missing_training_is_named(tmp_path):
    folder = tmp_path / "results/metrics/placing"
    folder.mkdir(parents=True)
    rng = np.random.default_rng(1)
    for name in ("a", "a-seed1", "b"):
        _rows(name, np.full(12, 0.5), rng).to_parquet(folder / f"{name}.parquet")
    with pytest.raises(SystemExit, match=r"b-seed1.parquet, .*b-seed2.parquet, .*a-seed2.parquet: missing"):
        trainings.main(["--results", str(tmp_path / "results"), "--tasks", "placing", "--better", "b", "--than",
                        "a", "--out", str(tmp_path / "x.json")])
