"""The maps' statistics against the hands' PV and SD (tohgs.metrics.map_statistics, scripts/map_statistics.py)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tohgs.metrics.bootstrap import BootstrapSettings
from tohgs.metrics.map_statistics import compare_rows, map_statistics

REPO = Path(__file__).resolve().parent.parent


def test_the_statistics_of_a_known_map():
    points = np.zeros((10, 3))
    points[0, 0], points[1, 0] = 0.01, 0.03  # two points 1 and 3 cm along x; the rest at the centroid
    contact = np.zeros((2, 10))
    contact[0, :2] = 1.0
    s = map_statistics(contact, points)
    assert np.allclose(s["mean_c2"], [0.2, 0.0]) and np.allclose(s["share_above_09"], [0.2, 0.0])
    assert np.allclose(s["offset_cm"], [2.0, 0.0])  # the contact-weighted centroid at 2 cm; an empty map at 0
    with pytest.raises(ValueError, match="map_statistics needs"):
        map_statistics(contact, points[:5])


def _rows(row_effect: float, seed: int) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Two rows of 12 objects x 3 configurations x 8 grasps whose SD is 0.5 cm per cm of contact offset plus
    noise; the second row's contact lies 1 cm farther out and it adds ``row_effect`` of its own."""
    rng = np.random.default_rng(seed)
    frames = []
    for row in (0, 1):
        keys = [(f"o{o}", c, s) for o in range(12) for c in range(3) for s in range(8)]
        obj, cfg, smp = map(list, zip(*keys))
        offset = rng.normal(1.0 + row, 0.5, len(keys))
        frames.append(pd.DataFrame({"object": obj, "config_index": cfg, "sample": smp,
                                    "mean_c2": rng.normal(0.2, 0.02, len(keys)),
                                    "share_above_09": rng.uniform(0, 0.02, len(keys)), "offset_cm": offset,
                                    "pv": rng.normal(1.0, 0.1, len(keys)),
                                    "sd": 0.5 * offset + row * row_effect + rng.normal(0, 0.2, len(keys))}))
    return frames[0], frames[1]


def test_the_maps_carry_a_difference_they_make_and_not_one_they_do_not():
    boot = BootstrapSettings(samples=200, seed=0)
    through_maps = compare_rows(*_rows(0.0, 0), "sd", boot)
    assert through_maps["row_alone"]["lo"] > 0.3  # the second row's SD is higher ...
    assert through_maps["row_given_maps"]["lo"] < 0 < through_maps["row_given_maps"]["hi"]  # ... through the offset
    assert through_maps["offset_cm"]["lo"] > 0 and through_maps["mean_c2"]["lo"] < 0 < through_maps["mean_c2"]["hi"]
    own = compare_rows(*_rows(1.0, 1), "sd", boot)  # a difference of the row's own stays when the maps enter
    assert own["row_given_maps"]["lo"] > 0.5, own["row_given_maps"]
    assert set(own["means"]) == {"first", "second"} and own["means"]["second"]["offset_cm"] > own["means"]["first"]["offset_cm"]


@pytest.mark.slow  # the smoke run: the end-to-end tests' fixture
def test_the_script_on_the_smoke_run(smoke_run, tmp_path):
    sys.path.insert(0, str(REPO / "scripts"))
    from map_statistics import main

    pair = "m-grasptta-ta:m-grasptta-gt"  # both in the smoke run's Table 2 (Ours (GT contact) comes later)
    out = main(["--results", str(smoke_run / "results"), "--tasks", "placing", "--pairs", pair,
                "--samples", "20", "--out", str(tmp_path / "m.json")])
    entry = out["placing"][pair]
    written = json.loads((tmp_path / "m.json").read_text())["placing"][pair]
    assert written["pv"]["row_alone"]["value"] == pytest.approx(entry["pv"]["row_alone"]["value"])
    for y in ("pv", "sd"):
        assert np.isfinite(entry[y]["row_alone"]["value"]) and entry[y]["row_alone"]["lo"] <= entry[y]["row_alone"]["hi"]
    assert 0 < entry["pv"]["means"]["first"]["mean_c2"] < 1
