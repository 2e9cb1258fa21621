"""Robust SD (SD under perturbed starts): cases with known answers, and its table columns and intervals."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import trimesh

from tohgs.metrics.bootstrap import BootstrapSettings, robust_stats
from tohgs.metrics.evaluate import COLUMNS, grasp_rng
from tohgs.metrics.quality import (DisplacementSimulator, RobustSDSettings, SDSettings, hand_quality,
                                   perturbed_displacements, surface_voxels)
from tohgs.metrics.tables import QualityThresholds, markdown, metric_table, summarize

HALF = 0.02  # the test cube's half size, m


@pytest.fixture(scope="module")
def cube(tmp_path_factory):
    mesh = trimesh.creation.box(extents=(2 * HALF,) * 3)
    path = tmp_path_factory.mktemp("cube") / "collision.obj"
    mesh.export(path)
    return mesh, path


def _closed_cup(gap: float) -> trimesh.Trimesh:
    """A closed box around the cube: its floor touches the cube's bottom, the walls and lid ``gap`` away."""
    inner = 2 * HALF + 2 * gap
    cup = trimesh.creation.box(extents=(inner, inner, 2 * HALF + gap)).subdivide_to_size(0.006)
    cup.apply_translation((0.0, 0.0, gap / 2))  # floor at z = -HALF
    return cup


def test_a_cube_in_a_closed_cup_stays_put_under_every_perturbation(cube):
    mesh, path = cube
    cup = _closed_cup(0.002)
    settings = RobustSDSettings(perturbations=6, offset=0.0005, solver_jitter=10)
    with DisplacementSimulator(path, np.zeros(3), SDSettings(gravity_direction="fixed")) as sim:
        sds = perturbed_displacements(sim, cup.vertices, cup.faces, settings, np.random.default_rng(0))
        still = perturbed_displacements(sim, cup.vertices, cup.faces, RobustSDSettings(perturbations=3, offset=0.0),
                                        np.random.default_rng(1))
        protocol = sim.displacement(cup.vertices, cup.faces)
    assert sds.shape == (6,)
    # zero at the simulator's resolution: a body resting on a Bullet triangle mesh settles by about a
    # millimetre (contact margins, restitution 0.5), unperturbed too; never a slip (the QR's 2 cm) or a fall
    assert protocol < 2e-3 and np.all(sds < 2e-3) and np.all(still < 2e-3), (protocol, sds, still)


def test_a_free_fall_moves_the_free_fall_distance_under_every_perturbation(cube):
    mesh, path = cube
    far = trimesh.creation.box(extents=(0.05, 0.05, 0.01))
    far.apply_translation((1.0, 0.0, 0.0))  # a 'hand' a metre away: nothing holds the cube
    sd = SDSettings(gravity_direction="fixed")
    settings = RobustSDSettings(perturbations=4)
    with DisplacementSimulator(path, np.zeros(3), sd) as sim:
        sds = perturbed_displacements(sim, far.vertices, far.faces, settings, np.random.default_rng(0))
    g, dt, n = 9.8, sd.time_step, sd.steps
    discrete = g * dt**2 * n * (n + 1) / 2  # Bullet's semi-implicit Euler: v += g dt, then x += v dt
    np.testing.assert_allclose(sds, discrete, rtol=0.01)
    assert abs(sds.mean() - 0.5 * g * (n * dt) ** 2) < 0.05 * discrete  # and the continuous 1/2 g t^2


def test_hand_quality_perturbs_the_first_grasps_only_and_reproducibly(cube):
    mesh, path = cube
    cup = _closed_cup(0.002)
    far = cup.vertices + [1.0, 0.0, 0.0]
    hands = np.stack([cup.vertices, far, far])
    settings = RobustSDSettings(perturbations=2, grasps_per_config=2)
    voxels = surface_voxels(mesh)
    with DisplacementSimulator(path, np.zeros(3), SDSettings(gravity_direction="fixed")) as sim:
        runs = [hand_quality(hands, cup.faces, np.arange(4), mesh, voxels, sim, robust=settings,
                             robust_rngs=[grasp_rng(0, "cube", 0, k) for k in range(3)]) for _ in range(2)]
        with pytest.raises(ValueError, match="one generator per hand"):
            hand_quality(hands, cup.faces, np.arange(4), mesh, voxels, sim, robust=settings, robust_rngs=None)
    p = runs[0]["sd_perturbed"]
    assert p.shape == (3, 2) and np.isnan(p[2]).all()  # the third grasp is past grasps_per_config
    assert np.all(p[0] < 2e-3) and np.all(p[1] > 0.09)  # held in the cup; falling freely
    np.testing.assert_array_equal(runs[0]["sd_perturbed"], runs[1]["sd_perturbed"])
    assert grasp_rng(0, "cube", 0, 1).random() != grasp_rng(0, "cube", 0, 2).random()


def _rows(sd, perturbed, config):
    n = len(sd)
    return pd.DataFrame({"task": "placing", "method": "ours", "object": "pb-x", "config_index": config,
                         "sample": np.arange(n), "pv": 0.0, "sd": sd, "contact_distance": 0.0, "init_opp": 0.0,
                         "goal_opp": 0.0, "ds": 1.0, "hand_vertices": 778, "kept": True,
                         "sd_perturbed": perturbed, "sd_palm": np.nan})[list(COLUMNS)]


def test_robust_columns_follow_their_definitions():
    # max_sd 2 cm: grasp 0 passes everywhere, grasp 1 passes once of four and its protocol SD passes,
    # grasp 2 fails everywhere, grasp 3 was not perturbed
    f = _rows(sd=[0.001, 0.015, 0.08, 0.05],
              perturbed=[[0.001, 0.002, 0.0, 0.001], [0.01, 0.05, 0.07, 0.09], [0.1, 0.1], []], config=[0, 0, 1, 1])
    t = QualityThresholds()
    rob = robust_stats(f, t.max_sd)
    assert len(rob) == 3
    np.testing.assert_allclose(rob.sd_robust, [0.001, 0.06, 0.1])
    np.testing.assert_allclose(rob.sd_pass, [1.0, 0.25, 0.0])
    np.testing.assert_allclose(rob.sd_unstable, [0.0, 1.0, 0.0])
    s = summarize(f, t)
    assert s["sd_robust"] == pytest.approx(100 * (0.001 + 0.06 + 0.1) / 3)
    assert s["sd_pass"] == pytest.approx(100 * 1.25 / 3) and s["sd_unstable"] == pytest.approx(100 / 3)
    assert s["qr"] == 50.0  # the protocol's QR is untouched by the perturbed SDs

    none = summarize(f.assign(sd_perturbed=[[] for _ in range(4)]), t)
    assert np.isnan(none["sd_robust"]) and np.isnan(none["sd_pass"])
    legacy = summarize(f.drop(columns="sd_perturbed"), t)  # metric files written before robust SD
    assert np.isnan(legacy["sd_unstable"]) and legacy["qr"] == 50.0


def test_robust_columns_get_intervals_around_their_value():
    rng = np.random.default_rng(0)
    n = 40
    sd = rng.uniform(0.0, 0.05, n)
    perturbed = [list(np.clip(s + rng.normal(0, 0.01, 3), 0, None)) for s in sd]
    f = _rows(sd=sd, perturbed=perturbed, config=np.arange(n) // 4).assign(object=[f"o{k // 8}" for k in range(n)])
    table = metric_table(f, ["placing"], ["ours"], {}, ["sd_avg", "sd_robust", "sd_pass", "sd_unstable"],
                         QualityThresholds(), bootstrap=BootstrapSettings(samples=300))
    row = table.iloc[0]
    for c in ("sd_robust", "sd_pass", "sd_unstable"):
        assert row[f"{c}_lo"] < row[c] < row[f"{c}_hi"], c
    assert "±" in markdown(table).splitlines()[2]
