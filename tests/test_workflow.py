"""End to end: the workflow on the smoke config (.test/config/config.yaml), then incremental reruns.

Runs in a copy of the workflow, config and library in a temporary folder, so the checks that touch code
or change settings never touch the repository's own results.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
import yaml

REPO = Path(__file__).resolve().parent.parent
pytestmark = pytest.mark.slow


def _snakemake(workdir: Path, *args: str, configfile: str = ".test/config/config.yaml") -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "snakemake", "--cores", "2", "--configfile", configfile, *args]
    return subprocess.run(cmd, cwd=workdir, capture_output=True, text=True, timeout=900)


def _stale_jobs(workdir: Path, configfile: str = ".test/config/config.yaml") -> dict[str, int]:
    """Dry run; returns {rule: number of jobs} that Snakemake would run."""
    out = _snakemake(workdir, "-n", "--quiet", "rules", configfile=configfile)
    assert out.returncode == 0, out.stderr[-3000:]
    text = out.stdout + out.stderr
    if "Nothing to be done" in text:
        return {}
    block = text.split("Job stats:", 1)[1]
    return {m.group(1): int(m.group(2)) for m in re.finditer(r"^(\w+)\s+(\d+)$", block, re.M) if m.group(1) != "total"}


@pytest.fixture(scope="module")
def smoke_run(tmp_path_factory) -> Path:
    work = tmp_path_factory.mktemp("smoke")
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for d in ("workflow", "config", "tohgs", ".test", "profiles"):
        shutil.copytree(REPO / d, work / d, ignore=ignore)
    out = _snakemake(work)
    assert out.returncode == 0, (out.stdout + out.stderr)[-5000:]
    return work


def test_smoke_run_outputs(smoke_run):
    cfg = yaml.safe_load((smoke_run / ".test/config/config.yaml").read_text())
    cat = pd.read_csv(smoke_run / "results/objects/catalog.csv", keep_default_na=False)
    src = cfg["objects"]["sources"]
    n_expected = src["pybullet_data"]["random_urdfs"] + src["pybullet_data"]["named"] + src["bricks"]["count"]
    assert len(cat) == n_expected
    ok = cat[cat.status == "ok"]
    assert len(ok) >= n_expected - 1
    for name in ok.name:
        d = smoke_run / "results/objects" / name
        assert (d / "mesh.obj").is_file() and (d / "collision.obj").is_file() and (d / "object.urdf").is_file()
    for task_set in ok.task_set.unique():
        splits = set(ok[ok.task_set == task_set].split)
        assert "train" in splits and "test" in splits, f"{task_set}: {splits}"
    assert (smoke_run / "results/objects/supports/supports.json").is_file()
    for png in ("objects.png", "hand.png"):
        assert (smoke_run / "results/figures" / png).stat().st_size > 20_000
    from tohgs.hand import HandAssets

    assert HandAssets.load(smoke_run / "results/hand/hand.npz").name == cfg["hand"]["model"]
    assert (smoke_run / "logs/objects/catalog.log").read_text().strip()


def test_nothing_to_do_after_a_finished_run(smoke_run):
    assert _stale_jobs(smoke_run) == {}


def _edit(path: Path) -> None:
    time.sleep(1.0)
    with open(path, "a") as fh:
        fh.write("# an edit\n")


def test_editing_assets_code_makes_exactly_the_objects_jobs_stale(smoke_run):
    n_objects = len(pd.read_csv(smoke_run / "results/objects/catalog.csv"))
    # Snakemake compares the checksums of small inputs: a touch without a change of content is no change.
    time.sleep(1.0)
    os.utime(smoke_run / "tohgs/assets/mesh.py")
    assert _stale_jobs(smoke_run) == {}
    _edit(smoke_run / "tohgs/assets/mesh.py")
    assert _stale_jobs(smoke_run) == {"all": 1, "prepare_object": n_objects, "catalog": 1, "objects_figure": 1,
                                      "supports": 1}
    assert _snakemake(smoke_run).returncode == 0
    _edit(smoke_run / "tohgs/viz/render.py")
    assert _stale_jobs(smoke_run) == {"all": 1, "objects_figure": 1, "hand_figure": 1}
    assert _snakemake(smoke_run).returncode == 0
    assert _stale_jobs(smoke_run) == {}


def test_changing_a_setting_makes_only_its_jobs_stale(smoke_run):
    cfg = yaml.safe_load((smoke_run / ".test/config/config.yaml").read_text())
    n_bricks = cfg["objects"]["sources"]["bricks"]["count"]
    n_objects = len(pd.read_csv(smoke_run / "results/objects/catalog.csv"))

    def stale_with(patch) -> dict[str, int]:
        changed = yaml.safe_load(yaml.safe_dump(cfg))
        block = changed
        *path, key = patch[0].split(".")
        for p in path:
            block = block[p]
        block[key] = patch[1]
        (smoke_run / "changed.yaml").write_text(yaml.safe_dump(changed))
        return _stale_jobs(smoke_run, configfile="changed.yaml")

    # The brick scale concerns the bricks only; the density every object; the split only the catalog.
    assert stale_with(("objects.sources.bricks.scale", 1.1)) == {
        "all": 1, "prepare_object": n_bricks, "catalog": 1, "objects_figure": 1}
    assert stale_with(("objects.density", 650.0)) == {
        "all": 1, "prepare_object": n_objects, "catalog": 1, "objects_figure": 1}
    assert stale_with(("objects.split.bricks", {"test": 0.5, "val": 0.0})) == {
        "all": 1, "catalog": 1, "objects_figure": 1}
    assert stale_with(("objects.supports.table", [1.2, 0.8, 0.05])) == {"all": 1, "supports": 1}
    # A hand setting concerns the hand only (a MANO file needs a path that exists).
    (smoke_run / "MANO_RIGHT.pkl").write_bytes(b"")
    changed = yaml.safe_load(yaml.safe_dump(cfg))
    changed["hand"] = {"model": "mano", "mano_path": "MANO_RIGHT.pkl"}
    (smoke_run / "changed.yaml").write_text(yaml.safe_dump(changed))
    assert _stale_jobs(smoke_run, configfile="changed.yaml") == {"all": 1, "hand_model": 1, "hand_figure": 1}
    # The dumps above sort the keys: the order of keys in a config file is not a change.
    assert stale_with(("seed", cfg["seed"])) == {}
