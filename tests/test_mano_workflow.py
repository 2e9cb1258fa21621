"""A user's MANO end to end (issue 22): the smoke workflow with ``hand.model: mano`` runs to Table 1.

The MANO file is the synthetic one of ``tests/synthetic_mano.py`` (MANO's pickle format on the anny hand's
geometry, with small random pose blend shapes), written into the run's temporary folder; a real
MANO_RIGHT.pkl is never fetched or used. The run is the smoke config (``.test/config/config.yaml``) with
:data:`MANO_CONFIG` layered over it (a second ``--configfile``), cut to one task, three objects and a
Table 1 of two cheap rows, and only Table 1 (and the hand) are asked for: a few minutes on 2 CPU cores
instead of the full smoke run's ~12 (docs/hand.md records the measured time).
"""

from __future__ import annotations

import copy
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

from synthetic_mano import make_synthetic_mano
from workflow_tools import copy_workflow, workflow_env

REPO = Path(__file__).resolve().parent.parent
pytestmark = pytest.mark.slow

#: Layered over the smoke config; ``hand.mano_path`` is filled in per run. One task (placing), its three
#: pybullet_data objects (no bricks, no named mesh), two configurations per object, a smaller synthesis
#: batch (the smoke schedule, which keeps ~half the grasps; fewer iterations left 1-5 of 32 per object),
#: shorter training of the two components Ours needs, and Table 1 of the Dataset row and Ours.
MANO_CONFIG = {
    "hand": {"model": "mano", "mano_path": None},
    "scenes": {"tasks": ["placing"], "n_configs": 2},
    "objects": {"sources": {"pybullet_data": {"random_urdfs": 3, "named": 0}, "bricks": {"count": 0},
                            "ycb": {"count": 0}}},
    "prior_grasps": {"synthesis": {"batch": 32}},
    "components": {"contact_diffuser": {"training": {"steps": 60}},
                   "grasp_diffuser": {"training": {"steps": 100}}},
    "tables": {"table1": {"rows": ["dataset", "ours"]}},
}
TARGETS = ("results/tables/table1.csv", "results/hand/hand.npz")
ROWS = {"dataset": "Dataset", "ours": "Ours"}  # the methods' labels (the schema's default methods)


@pytest.fixture(scope="module")
def mano_run(tmp_path_factory) -> SimpleNamespace:
    from tohgs.hand import load_hand_assets

    work = copy_workflow(tmp_path_factory.mktemp("mano"))
    anny = load_hand_assets("anny")  # the synthetic file's geometry (cached under ~/.cache/tohgs)
    mano_path = work / "MANO_RIGHT.pkl"
    make_synthetic_mano(anny, mano_path)
    cfg = copy.deepcopy(MANO_CONFIG)
    cfg["hand"]["mano_path"] = str(mano_path)
    (work / "mano.yaml").write_text(yaml.safe_dump(cfg))
    cmd = [sys.executable, "-m", "snakemake", *TARGETS, "--cores", "2", "--configfile",
           ".test/config/config.yaml", "mano.yaml"]
    start = time.monotonic()
    out = subprocess.run(cmd, cwd=work, capture_output=True, text=True, timeout=1800, env=workflow_env(work), stdin=subprocess.DEVNULL)
    seconds = time.monotonic() - start
    assert out.returncode == 0, (out.stdout + out.stderr)[-5000:]
    return SimpleNamespace(work=work, mano_path=mano_path, anny=anny, seconds=seconds)


def test_the_hand_stage_extracts_the_users_mano_file(mano_run, capsys):
    from tohgs.data.grasps import read_prior_grasps
    from tohgs.hand import HandAssets
    from tohgs.hand.mano_backend import read_mano_pickle

    with capsys.disabled():
        print(f"\nMANO smoke run to Table 1: {mano_run.seconds:.0f} s")
    hand = HandAssets.load(mano_run.work / "results/hand/hand.npz")
    raw = read_mano_pickle(mano_run.mano_path)
    assert hand.name == "mano" and hand.meta["backend"] == "mano" and hand.meta["source"] == str(mano_run.mano_path)
    # the file's arrays, as they are: its template and its pose blend shapes (anny has none)
    assert len(hand.rest_vertices) == len(raw["v_template"])
    np.testing.assert_array_equal(hand.rest_vertices, raw["v_template"])
    assert mano_run.anny.pose_dirs is None and hand.pose_dirs is not None
    np.testing.assert_array_equal(hand.pose_dirs, raw["posedirs"])
    # the prior grasps were synthesised with it
    stores = sorted((mano_run.work / "results/grasps/prior").glob("*.zarr"))
    assert len(stores) == 3
    for st in stores:
        assert read_prior_grasps(st, filtered=True).attrs["hand"] == "mano", st.name


def test_table1_has_its_two_rows_with_finite_numbers(mano_run):
    table = pd.read_csv(mano_run.work / "results/tables/table1.csv")
    assert list(zip(table.task, table.method)) == [("placing", label) for label in ROWS.values()]
    assert (table.grasps > 0).all() and (table.configs > 0).all()
    for col in ("pv_avg", "sd_avg", "cr", "qr", "ds", "init_opp", "goal_opp", "ts"):
        assert table[col].map(math.isfinite).all(), (col, table[col].tolist())
    assert "| Task |" in (mano_run.work / "results/tables/table1.md").read_text()


def test_the_evaluated_grasps_were_posed_with_the_mano_hand(mano_run):
    """DS (the summed vertex distance between a configuration's hands) as the evaluation wrote it equals
    DS of the predicted grasp vectors posed with the MANO file's hand, and not with anny's: the two share
    the rest mesh, but the MANO hand adds its pose blend shapes (a 1e-3 relative change of DS, far above the
    1e-9 agreement)."""
    from tohgs.data.predictions import read_predictions
    from tohgs.hand.mano_backend import load_mano_assets
    from tohgs.metrics.evaluate import diversity

    mano = load_mano_assets(mano_run.mano_path)
    compared = 0
    for method in ROWS:
        arrays, attrs = read_predictions(mano_run.work / f"results/predictions/placing/{method}.zarr")
        metrics = pd.read_parquet(mano_run.work / f"results/metrics/placing/{method}.parquet")
        assert (metrics.hand_vertices == len(mano.rest_vertices)).all()
        ds = metrics.groupby(["object", "config_index"]).ds.first()
        for i in range(len(arrays["object_id"])):
            kept = np.asarray(arrays["kept"][i], bool)
            grasps = arrays["grasp_init"][i][kept]
            if len(np.unique(grasps, axis=0)) < 2:  # one grasp, or one repeated (a configuration with a single
                continue  # task grasp gives the Dataset row that grasp S times): DS is 0 with either hand
            written = ds[(attrs["objects"][int(arrays["object_id"][i])], int(arrays["config_index"][i]))]
            with_mano, with_anny = diversity(mano.vertices(grasps)), diversity(mano_run.anny.vertices(grasps))
            assert written == pytest.approx(with_mano, rel=1e-9), (method, i)
            assert abs(written - with_anny) > 1e-5 * written, (method, i, written, with_anny)
            compared += 1
    assert compared >= 2
