"""The official dataset through the workflow (issue 22): with ``official.import_dir`` the smoke workflow trains
and evaluates on an import of the synthetic official tree (tests/synthetic_official.py) and its predictions
export back to the official test configurations.

The run is the smoke config (``.test/config/config.yaml``) with :data:`OFFICIAL_CONFIG` layered over it:
Placing only, Table 1 of the Dataset row (which the official test configurations cannot have: no
ground-truth grasps) and Ours, and only Table 1 and the dataset summary are asked for (46 s on 2 CPU cores
in CI; docs/official_dataset.md).
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
import yaml

from synthetic_official import DS, make_official_tree
from workflow_tools import copy_workflow, job_stats, workflow_env

pytestmark = pytest.mark.slow

#: Layered over the smoke config: the import (relative to the run's folder), one task, Table 1 of two rows,
#: the predictions figure of Ours only (so only Ours' components train).
OFFICIAL_CONFIG = {
    "official": {"import_dir": "official"},
    "scenes": {"tasks": ["placing"]},
    "tables": {"table1": {"rows": ["dataset", "ours"]}},
    "figures": {"methods": ["ours"]},
}
TARGETS = ("results/tables/table1.csv", "results/maps/summary.csv")


def _snakemake(work: Path, *args: str, timeout: int = 1800) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "snakemake", *args, "--cores", "2", "--configfile", ".test/config/config.yaml",
           "official.yaml"]
    return subprocess.run(cmd, cwd=work, capture_output=True, text=True, timeout=timeout, env=workflow_env(work),
                          stdin=subprocess.DEVNULL)


@pytest.fixture(scope="module")
def official_run(tmp_path_factory) -> SimpleNamespace:
    from tohgs.official.importer import import_official
    from tohgs.hand import load_hand_assets

    work = copy_workflow(tmp_path_factory.mktemp("official-run"))
    tree = make_official_tree(work / "tree")
    report = import_official(tree["root"], work / "official", load_hand_assets("anny"), tasks=["placing"])
    (work / "official.yaml").write_text(yaml.safe_dump(OFFICIAL_CONFIG))
    dry = _snakemake(work, *TARGETS, "--dry-run", timeout=300)
    assert dry.returncode == 0, (dry.stdout + dry.stderr)[-5000:]
    start = time.monotonic()
    out = _snakemake(work, *TARGETS)
    seconds = time.monotonic() - start
    assert out.returncode == 0, (out.stdout + out.stderr)[-5000:]
    return SimpleNamespace(work=work, tree=tree, report=report, jobs=job_stats(dry.stdout), log=out.stdout + out.stderr,
                           seconds=seconds)


def test_the_import_replaces_the_generating_stages(official_run, capsys):
    with capsys.disabled():
        print(f"\nofficial smoke run to Table 1: {official_run.seconds:.0f} s")
    jobs, work = official_run.jobs, official_run.work
    # every imported object (targets and the obstacle); both targets' scenes and grasps (the dataset summary
    # reads them: its scene difficulty measures every configuration's obstacle gaps); the test JSON's
    # configurations
    assert jobs["official_object"] == 3 and jobs["official_scenes"] == 2 and jobs["official_task_grasps"] == 2
    assert jobs["official_test_scenes"] == 1 and jobs["supports"] == 1
    assert not {"prepare_object", "scenes", "prior_synthesis", "task_grasps"} & set(jobs)
    assert not (work / "results/grasps/prior").exists()
    for name in ("off-can-b", "off-box-c"):
        copied, imported = work / "results/objects" / name, work / "official/objects" / name
        files = [sorted(p.name for p in d.iterdir() if not p.name.startswith(".")) for d in (copied, imported)]
        assert files[0] == files[1]  # (Snakemake marks a folder output with its .snakemake_timestamp)
        assert (copied / "meta.json").read_text() == (imported / "meta.json").read_text()
    assert "left out of the tables and figures (they read ground-truth grasps): dataset" in official_run.log


def test_the_shards_hold_the_official_splits(official_run):
    """Training on train.txt's grasps (mug_a: 3 rows in 2 scenes); the test shard holds the first
    maps.test_configs (2) of the test JSON's 3 configurations, in order, and no grasps."""
    from tohgs.data.maps import read_map_shard

    work = official_run.work
    train = read_map_shard(work / "results/maps/placing/train/shard-0.zarr")
    test = read_map_shard(work / "results/maps/placing/test/shard-0.zarr")
    assert train.attrs["objects"] == ["off-mug-a"] and train.n_configs == 2 and train.n_grasps == 3
    assert test.attrs["objects"] == ["off-can-b"] and test.n_grasps == 0
    assert test.arrays["config_index"].tolist() == [0, 1]


def test_table1_has_ours_and_says_why_the_dataset_row_is_empty(official_run):
    table = pd.read_csv(official_run.work / "results/tables/table1.csv")
    ours = table[table.method == "Ours"]
    assert len(ours) == 1 and int(ours.configs.iloc[0]) == 2 and int(ours.grasps.iloc[0]) > 0
    for col in ("pv_avg", "sd_avg", "cr", "qr", "ds", "init_opp", "goal_opp", "ts"):
        assert math.isfinite(float(ours[col].iloc[0])), col
    md = (official_run.work / "results/tables/table1.md").read_text()
    assert "the official test configurations have no ground-truth grasps" in md


def test_predictions_export_to_the_official_test_configurations(official_run):
    """Ours' predictions, exported, name the test JSON's configurations: each grasp's target pose and
    obstacles are the JSON entry's (exactly, after the frame round trip), and the hand is at the object."""
    from tohgs.official.exporter import export_official
    from tohgs.official.format import load_official_npy
    from tohgs.hand import HandAssets

    work = official_run.work
    hand = HandAssets.load(work / "results/hand/hand.npz")
    written = export_official(work / "results/predictions/placing/ours.zarr", work / "results/test_scenes", hand,
                              work / "export")
    assert sorted(written) == ["can_b"]
    out = load_official_npy(written["can_b"].read_bytes())
    src = json.loads((official_run.tree["root"] / DS / "placing/test/can_b.json").read_text())
    assert sorted(set(out["config"])) == [0, 1] and out["grasped_obj"] == "can_b"
    for i, c in enumerate(out["config"]):
        np.testing.assert_allclose(out["init_pose"][i], src["init_pose"][c], atol=1e-9)
        np.testing.assert_allclose(out["goal_pose"][i], src["goal_pose"][c], atol=1e-9)
        assert out["obstacle_name"][i] == src["obstacle_name"][c]
        assert np.linalg.norm(out["init_hand_vertex"][i].mean(0) - np.asarray(src["init_pose"][c][:3])) < 0.3


def test_a_task_the_import_lacks_is_refused(official_run):
    cfg = {**OFFICIAL_CONFIG, "scenes": {"tasks": ["placing", "stacking"]}}
    (official_run.work / "lacking.yaml").write_text(yaml.safe_dump(cfg))
    cmd = [sys.executable, "-m", "snakemake", "--dry-run", "--cores", "1", "--configfile", ".test/config/config.yaml",
           "lacking.yaml"]
    out = subprocess.run(cmd, cwd=official_run.work, capture_output=True, text=True, timeout=300,
                         env=workflow_env(official_run.work), stdin=subprocess.DEVNULL)
    assert out.returncode != 0
    assert "config key 'scenes.tasks': stacking not in the import official" in out.stdout + out.stderr
