"""Seeds (config key ``seeds``): the replicas of methods and components, and the tables that pool them."""

from __future__ import annotations

import copy

import numpy as np
import pandas as pd
import pytest

from tohgs.config import ConfigError, add_seed_replicas, validate_config
from tohgs.metrics.evaluate import COLUMNS
from tohgs.metrics.tables import QualityThresholds, markdown, metric_table, read_metrics, summarize


def test_one_seed_zero_leaves_the_config_as_written():
    cfg = validate_config({})
    before = copy.deepcopy(cfg)
    replicas = add_seed_replicas(cfg, ["ours", "f-grasptta"])
    assert cfg == before
    assert replicas["ours"] == ["ours"] and replicas["f-grasptta"] == ["f-grasptta"]
    assert replicas["grasptta"] == ["grasptta"]  # what a filtered method is of comes with it


def test_replicas_carry_their_seed_and_name_their_own_components():
    cfg = validate_config({"seeds": [0, 2, 5], "training": {"seed": 10}, "prediction": {"seed": 3},
                           "components": {"grasp_diffuser": {"kind": "grasp_diffuser", "training": {"seed": 7}}}})
    replicas = add_seed_replicas(cfg, ["ours", "f-grasptta", "dataset"])
    assert replicas["ours"] == ["ours", "ours-seed2", "ours-seed5"]
    assert replicas["f-grasptta"] == ["f-grasptta", "f-grasptta-seed2", "f-grasptta-seed5"]
    m, comps = cfg["methods"], cfg["components"]
    assert m["ours-seed5"]["contact"] == "contact_diffuser-seed5" and m["ours-seed5"]["grasp"] == "grasp_diffuser-seed5"
    assert m["ours-seed5"]["settings"]["seed"] == 3 + 5 and m["ours-seed5"]["label"] == m["ours"]["label"]
    assert m["ours-gt-contact"] == validate_config({})["methods"]["ours-gt-contact"]  # not asked for: no replica
    assert "ours-gt-contact-seed2" not in m
    assert m["f-grasptta-seed2"]["of"] == "grasptta-seed2" and m["grasptta-seed2"]["cvae"] == "grasp_cvae-seed2"
    assert m["dataset-seed2"]["settings"]["seed"] == 5
    assert comps["contact_diffuser-seed2"]["training"]["seed"] == 10 + 2  # the training block's seed
    assert comps["grasp_diffuser-seed2"]["training"]["seed"] == 7 + 2  # the component's own overlay
    assert comps["grasp_diffuser-seed2"]["network"] == comps["grasp_diffuser"]["network"]
    assert "seed" not in cfg["methods"]["ours"]["settings"]  # the first seed, 0: untouched


def test_a_first_seed_other_than_zero_seeds_the_named_blocks():
    cfg = validate_config({"seeds": [4]})
    replicas = add_seed_replicas(cfg, ["ours"])
    assert replicas["ours"] == ["ours"]
    assert cfg["methods"]["ours"]["settings"]["seed"] == 4
    assert cfg["components"]["contact_diffuser"]["training"]["seed"] == 4


def test_seeds_are_validated():
    with pytest.raises(ConfigError, match="seeds"):
        validate_config({"seeds": [0, 0]})
    with pytest.raises(ConfigError, match="seeds"):
        validate_config({"seeds": []})


def _rows(method, seed, qr_good):
    """One configuration of 10 grasps, ``qr_good`` of them of quality."""
    n = 10
    good = np.arange(n) < qr_good
    return pd.DataFrame({"task": "placing", "method": method, "object": "pb-x", "config_index": 0,
                         "sample": np.arange(n), "pv": 0.0, "sd": np.where(good, 0.01, 0.05),
                         "contact_distance": 0.0, "init_opp": 0.0, "goal_opp": 0.0, "ds": 0.1 + seed,
                         "hand_vertices": 778, "kept": True,
                         "sd_perturbed": [[] for _ in range(n)], "sd_palm": np.nan})[list(COLUMNS)]


def test_tables_pool_the_seeds_and_add_their_spread(tmp_path):
    paths = []
    for method, seed, good in [("ours", 0, 8), ("ours-seed1", 1, 4), ("ours-seed2", 2, 6), ("other", 0, 5)]:
        p = tmp_path / f"{method}.parquet"
        _rows(method, seed, good).to_parquet(p)
        paths.append(p)
    replicas = {"ours": {"ours": 0, "ours-seed1": 1, "ours-seed2": 2}, "other": {"other": 0}}
    rows = read_metrics(paths, replicas)
    assert sorted(rows.method.unique()) == ["other", "ours"] and sorted(rows.seed.unique()) == [0, 1, 2]
    t = QualityThresholds()
    s = summarize(rows[rows.method == "ours"], t)
    assert s["qr"] == pytest.approx(60.0) and s["grasps"] == 30 and s["configs"] == 1
    assert s["ds"] == pytest.approx(1.1)  # the mean of each seed's DS of the configuration
    table = metric_table(rows, ["placing"], ["ours", "other"], {}, ["qr", "ts", "configs"], t)
    assert table.qr_seed_sd.iloc[0] == pytest.approx(np.std([80, 40, 60], ddof=1))
    assert table.ts_seed_sd.iloc[0] == pytest.approx(np.std([0.8, 0.4, 0.6], ddof=1))
    assert np.isnan(table.qr_seed_sd.iloc[1])  # one seed: no spread
    assert "TS sd (seeds)" in markdown(table)
    one = metric_table(read_metrics(paths[:1]), ["placing"], ["ours"], {}, ["qr", "ts"], t)
    assert "ts_seed_sd" not in one.columns  # a single seed's table is as before
