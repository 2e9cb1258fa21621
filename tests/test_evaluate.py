"""Evaluation metrics (DS, OPP, per-configuration grasp metrics) and Table 1 on cases with known answers."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import trimesh

from tohgs.assets.manifest import record_object_files
from tohgs.geometry.scene import SceneCollider
from tohgs.metrics.evaluate import COLUMNS, _ObjectAssets, diversity, grasp_metrics, occupied_fraction
from tohgs.metrics.quality import DisplacementSimulator, SDSettings, surface_voxels
from tohgs.metrics.tables import METRIC_COLUMNS, QualityThresholds, markdown, metric_table, qr_grid, summarize


def test_diversity_is_zero_for_identical_hands_and_the_summed_shift_otherwise():
    rng = np.random.default_rng(0)
    v = rng.normal(size=(50, 3))
    assert diversity(np.stack([v, v, v])) == 0.0
    shifted = np.stack([v, v + [0.01, 0, 0], v + [0.03, 0, 0]])
    # pairs: 0.01, 0.03, 0.02 per vertex, 50 vertices
    assert diversity(shifted) == pytest.approx(50 * (0.01 + 0.03 + 0.02) / 3)
    assert diversity(v[None]) == 0.0


def test_occupied_fraction_counts_vertices_inside_the_scene():
    table = trimesh.creation.box(extents=(1.0, 1.0, 0.1))  # top face at z = 0.05
    collider = SceneCollider([table])
    pts = np.zeros((2, 4, 3))
    pts[0, :, 2] = [0.2, 0.2, 0.2, 0.2]  # all above the table
    pts[1, :, 2] = [0.2, 0.0, -0.02, 0.3]  # two of four inside
    np.testing.assert_allclose(occupied_fraction(pts, collider), [0.0, 0.5])


@pytest.fixture(scope="module")
def cube_assets(tmp_path_factory):
    mesh = trimesh.creation.box(extents=(0.04, 0.04, 0.04))
    path = tmp_path_factory.mktemp("cube") / "collision.obj"
    mesh.export(path)
    return _ObjectAssets(mesh, surface_voxels(mesh), path, np.asarray(mesh.vertices).mean(0))


def test_grasp_metrics_of_a_clear_and_a_sunk_hand_at_a_moved_pose(cube_assets):
    """A box 'hand' beside the cube at its world pose: no PV, a positive contact distance, the cube falls
    (SD large); the same box sunk into the cube: PV > 0 and a negative distance; OPP against a table."""
    pose = np.array([0.3, -0.2, 0.5, 0, 0, np.sin(0.3), np.cos(0.3)])  # moved and turned about z
    slab = trimesh.creation.box(extents=(0.1, 0.1, 0.02)).subdivide_to_size(0.004)  # vertices on its faces
    clear = slab.vertices + [0.3, -0.2, 0.5 - 0.06]  # 5 cm below the cube's centre, 3 cm under its bottom
    sunk = slab.vertices + [0.3, -0.2, 0.5 - 0.02]  # half into the cube
    verts = np.stack([clear, sunk])
    table = trimesh.creation.box(extents=(1.0, 1.0, 0.1))
    table.apply_translation((0.3, -0.2, 0.5 - 0.06 - 0.05))  # top face through the clear slab's centre
    sd = SDSettings(gravity_direction="fixed")
    with DisplacementSimulator(cube_assets.collision, cube_assets.vertex_mean, sd) as sim:
        m = grasp_metrics(verts, verts, slab.faces, np.arange(4), cube_assets, pose, SceneCollider([table]), 0.001, sim)
    assert m["pv"][0] == 0.0 and m["pv"][1] > 1e-6
    assert m["contact_distance"][0] == pytest.approx(0.03, abs=1e-3) and m["contact_distance"][1] < 0
    assert 0.02 < m["sd"][0] < 0.035  # nothing holds the cube: it falls onto the slab 3 cm below
    np.testing.assert_allclose(m["init_opp"], m["goal_opp"])
    assert 0.2 < m["init_opp"][0] < 0.8 and m["init_opp"][1] == 0.0


def _rows(pv, sd, init_opp, goal_opp, method="ours", task="placing", config=None, kept=None):
    n = len(pv)
    config = np.zeros(n, int) if config is None else np.asarray(config)
    return pd.DataFrame({"task": task, "method": method, "object": "pb-x", "config_index": config,
                         "sample": np.arange(n), "pv": pv, "sd": sd, "contact_distance": 0.0,
                         "init_opp": init_opp, "goal_opp": goal_opp, "ds": config * 1.0 + 1.0,
                         "hand_vertices": 778, "kept": True if kept is None else kept,
                         "sd_perturbed": [[] for _ in range(n)], "sd_palm": np.nan})[list(COLUMNS)]


def test_summary_numbers_follow_their_definitions():
    f = _rows(pv=[0.0, 1e-6, 5e-6, 2e-6], sd=[0.01, 0.03, 0.01, 0.015], init_opp=[0.0, 0.1, 0.0, 0.1],
              goal_opp=[0.2, 0.0, 0.0, 0.0], config=[0, 0, 1, 1])
    s = summarize(f, QualityThresholds())
    assert s["cr"] == pytest.approx(75.0)
    assert s["qr"] == pytest.approx(50.0)  # grasps 0 and 3
    assert s["pv_avg"] == pytest.approx(2.0) and s["sd_avg"] == pytest.approx(1.625)
    assert s["init_opp"] == pytest.approx(5.0) and s["goal_opp"] == pytest.approx(5.0)
    assert s["ts"] == pytest.approx(0.5 * 0.95 * 0.95)
    assert s["ds"] == pytest.approx(1.5)  # configurations' DS 1 and 2
    assert s["ds_per_vertex"] == pytest.approx(1.5 / 778 * 100)  # cm per vertex of the 778-vertex hand
    assert s["grasps"] == 4 and s["configs"] == 2
    assert np.isnan(s["missing"]) and summarize(f, QualityThresholds(), task_configs=3)["missing"] == 1
    assert np.isnan(s["sd_palm_avg"]) and np.isnan(s["qr_palm"])  # evaluated without the palm's SD
    palm = summarize(f.assign(sd_palm=[0.01, 0.01, 0.01, 0.03]), QualityThresholds())
    assert palm["sd_palm_avg"] == pytest.approx(1.5) and palm["qr_palm"] == pytest.approx(50.0)  # grasps 0 and 1
    # a looser SD threshold counts grasp 1 too
    assert summarize(f, QualityThresholds(max_sd=0.04))["qr"] == pytest.approx(75.0)
    assert s["discarded"] == 0


def test_discarded_grasps_are_counted_and_left_out_and_a_row_with_none_kept_is_zero():
    f = _rows(pv=[0.0, np.nan, 5e-6, np.nan], sd=[0.01, np.nan, 0.01, np.nan], init_opp=[0.0, np.nan, 0.2, np.nan],
              goal_opp=[0.0, np.nan, 0.0, np.nan], config=[0, 0, 1, 1], kept=[True, False, True, False])
    s = summarize(f, QualityThresholds())
    assert s["grasps"] == 2 and s["discarded"] == 2 and s["qr"] == pytest.approx(50.0)
    assert s["init_opp"] == pytest.approx(10.0) and s["ts"] == pytest.approx(0.5 * 0.9)
    none = summarize(f.assign(kept=False), QualityThresholds())
    assert none["discarded"] == 4 and none["grasps"] == 0
    assert all(none[k] == 0.0 for k in ("qr", "ts", "pv_avg", "init_opp", "goal_opp", "ds"))
    assert qr_grid(f.assign(kept=False), ["placing"], ["ours"], {}, [3e-6], [0.02]).qr.isna().all()
    t = metric_table(f, ["placing"], ["ours"], {}, ["qr", "ts", "discarded"], QualityThresholds(), ["Ours (OC)"])
    assert list(t.method) == ["ours", "Ours (OC)"] and np.isnan(t.qr.iloc[1]) and t.discarded.iloc[0] == 2
    md = markdown(t, notes={"Ours (OC)": "needs the object-centric contact predictor"})
    assert "| placing | Ours (OC)* | – | – | – |" in md and "* Ours (OC): needs the object-centric" in md


LABELS = {"dataset": "Dataset", "ours": "Ours"}


def test_a_table_orders_rows_labels_them_and_leaves_missing_methods_empty():
    rows = pd.concat([_rows([0.0], [0.0], [0.0], [0.0], method="dataset"),
                      _rows([1e-5], [0.05], [0.0], [0.0], method="ours", task="stacking")])
    t = metric_table(rows, ["placing", "stacking"], ["dataset", "ours"], LABELS, list(METRIC_COLUMNS), QualityThresholds())
    assert list(zip(t.task, t.method)) == [("placing", "Dataset"), ("placing", "Ours"), ("stacking", "Dataset"),
                                           ("stacking", "Ours")]
    assert t.qr.iloc[0] == 100.0 and t.qr.iloc[3] == 0.0
    assert np.isnan(t.qr.iloc[1]) and t.grasps.iloc[1] == 0
    md = markdown(t)
    assert md.count("\n") == 2 + 4 and "| placing | Dataset |" in md and "–" in md
    few = metric_table(rows, ["placing"], ["ours", "dataset"], {}, ["ts", "qr"], QualityThresholds())
    assert list(few.columns) == ["task", "method", "ts", "qr"] and list(few.method) == ["ours", "dataset"]
    with pytest.raises(ValueError, match="unknown table columns"):
        metric_table(rows, ["placing"], ["ours"], {}, ["tss"], QualityThresholds())


def test_qr_grid_is_monotone_in_both_thresholds():
    rng = np.random.default_rng(1)
    f = _rows(pv=rng.uniform(0, 5e-6, 200), sd=rng.uniform(0, 0.04, 200), init_opp=np.zeros(200),
              goal_opp=np.zeros(200))
    g = qr_grid(f, ["placing"], ["ours"], LABELS, [1e-6, 2e-6, 3e-6, 4e-6], [0.01, 0.02, 0.03])
    assert len(g) == 12
    q = g.pivot(index="max_pv_cm3", columns="max_sd_cm", values="qr").to_numpy()
    assert (np.diff(q, axis=0) >= 0).all() and (np.diff(q, axis=1) >= 0).all() and q[-1, -1] > q[0, 0]


def test_reference_grasps_evaluate_collision_free_at_both_poses(built, tmp_path):  # noqa: F811
    """The dataset row end to end on the tiny dataset: ground-truth grasps in the world frame, carried to
    the goal, one metric row per grasp, no hand vertex inside the table at either pose."""
    from tohgs.data.maps import read_map_shard
    from tohgs.data.predictions import read_predictions
    from tohgs.geometry.grasp import transform_grasp
    from tohgs.methods.predict import predict
    from tohgs.metrics.evaluate import evaluate_predictions

    tmp, hand, _, _, _ = built
    shard = tmp / "shard-0.zarr"
    arrays = predict("placing", "dataset", {"label": "Dataset", "kind": "reference"}, [shard], {},
                     {"samples": 4, "seed": 0, "device": "cpu"}, tmp_path / "dataset.zarr")
    sh = read_map_shard(shard)
    stored, attrs = read_predictions(tmp_path / "dataset.zarr")
    assert attrs["method"] == "dataset" and stored["grasp_init"].shape == (sh.n_configs, 4, 51)
    wrist = np.asarray(sh.attrs["hand_wrist"])
    for c in range(sh.n_configs):
        truth = sh.grasp[sh.grasp_config == c].astype(np.float64) + np.r_[sh.centroid[c], np.zeros(48)]
        # every drawn grasp is one of the configuration's own, in the world frame
        assert all(np.abs(truth - g).max(1).min() < 1e-5 for g in arrays["grasp_init"][c])
        np.testing.assert_allclose(arrays["grasp_goal"][c], transform_grasp(arrays["grasp_init"][c],
                                                                           sh.goal_transform[c], wrist), atol=1e-6)
    mesh = trimesh.load(tmp / "objects/brick-cube/mesh.obj", force="mesh")
    mesh.export(tmp / "objects/brick-cube/collision.obj")  # the cube is convex: its own decomposition
    record_object_files(tmp / "objects/brick-cube", {"name": "brick-cube"}, ["mesh.obj", "collision.obj"])
    rows = evaluate_predictions(tmp_path / "dataset.zarr", [tmp / "scenes/brick-cube.zarr"], tmp / "objects",
                                tmp / "objects/supports/supports.json", hand.assets, {"gravity_direction": "fixed"})
    assert len(rows) == sh.n_configs * 4 and list(rows.columns) == list(COLUMNS)
    assert (rows.init_opp == 0).all() and (rows.goal_opp == 0).all()
    assert (rows.pv == 0).all() and (rows.contact_distance > 0).all()  # 5 mm above the top face
    assert (rows.hand_vertices == hand.rest_vertices.shape[0]).all()
    # two cores: SD (and robust SD) in two worker processes, the same rows
    robust = {"perturbations": 2, "grasps_per_config": 2}
    one, two = (evaluate_predictions(tmp_path / "dataset.zarr", [tmp / "scenes/brick-cube.zarr"], tmp / "objects",
                                     tmp / "objects/supports/supports.json", hand.assets, {"gravity_direction": "fixed"},
                                     robust_sd=robust, palm_sd=True, threads=threads) for threads in (1, 2))
    pd.testing.assert_frame_equal(one, two)
    assert one.sd_perturbed.map(len).sum() == sh.n_configs * 2 * 2
    assert one.sd_palm.notna().all() and rows.sd_palm.isna().all()  # the palm's SD only when asked


def test_the_paper_protocol_pulls_along_plus_y_of_the_scene_and_the_palm_column_out_of_the_palm(cube_assets, repo):
    """The default evaluation is the official code's: gravity (0, 9.8, 0) m/s^2 in the world frame, the same
    for every hand wherever its palm is. Physically: a slab on the cube's +y side holds it (the pull is
    into the slab), one under it (where -z gravity would rest the cube) does not; the palm column pulls
    out of the palm, so the slab under the cube, whose palm is below, loses the cube either way."""
    from tohgs.config import load_config
    from tohgs.metrics.quality import palm_gravity, sd_gravity

    cfg = load_config(repo / "config" / "config.yaml")
    g = cfg["evaluation"]["sd_gravity"]
    assert g == {"direction": "fixed", "vector": [0.0, 9.8, 0.0]} and cfg["evaluation"]["pv_mesh"] == "collision"
    settings = SDSettings(**{**cfg["metrics"]["sd"], "gravity_direction": g["direction"], "gravity": tuple(g["vector"])})
    palms = np.array([[0.0, 0.0, -0.05], [0.05, 0.0, 0.0], [0.0, -0.05, 0.0]])
    np.testing.assert_array_equal(sd_gravity(settings, palms, np.zeros(3)), np.tile([0.0, 9.8, 0.0], (3, 1)))
    # slabs 4 x 4 cm wide, 1 cm thick, touching the cube (side 4 cm, centred at the origin) on +y and on -z
    side = trimesh.creation.box(extents=(0.06, 0.01, 0.06)).subdivide_to_size(0.004)
    below = trimesh.creation.box(extents=(0.06, 0.06, 0.01)).subdivide_to_size(0.004)
    on_y, under = side.vertices + [0, 0.0252, 0], below.vertices + [0, 0, -0.0252]
    with DisplacementSimulator(cube_assets.collision, cube_assets.vertex_mean, settings) as sim:
        assert sim.displacement(on_y, side.faces) < 0.003  # pulled into the slab
        assert sim.displacement(under, below.faces) > 0.05  # pulled sideways along it: free fall is 10.7 cm
        up = palm_gravity(under.mean(0, keepdims=True), np.zeros(3))[0]
        np.testing.assert_allclose(up, [0, 0, 9.8], atol=1e-9)  # out of a palm below: upwards
        assert sim.displacement(under, below.faces, gravity=up) > 0.05
    rows = grasp_metrics(np.stack([on_y, under]), np.stack([on_y, under]), side.faces, np.arange(4), cube_assets,
                         np.array([0, 0, 0, 0, 0, 0, 1.0]), SceneCollider([trimesh.creation.box((0.1, 0.1, 0.1),
                         transform=trimesh.transformations.translation_matrix([1, 1, 1]))]), 0.001,
                         DisplacementSimulator(cube_assets.collision, cube_assets.vertex_mean, settings), palm_sd=True)
    assert rows["sd"][0] < 0.003 and rows["sd_palm"].shape == (2,) and np.isfinite(rows["sd_palm"]).all()


def test_ground_truth_rows_read_the_same_grasps_of_every_configuration(built):  # noqa: F811
    """Paired rows: the Dataset row and a ground-truth-contact row of one seed read identical task grasps
    per configuration (ids from ground_truth_pick), whatever random stream the method is given; another
    seed reorders them."""
    import torch

    from tohgs.data.batch import Batch
    from tohgs.data.maps import MapDataset, read_map_shard
    from tohgs.methods.base import ground_truth_pick, gt_rows
    from tohgs.methods.contact_grasp import ContactGrasp
    from tohgs.methods.reference import Reference

    tmp = built[0]
    shard = read_map_shard(tmp / "shard-0.zarr")
    data = MapDataset([tmp / "shard-0.zarr"], per="config")
    cpu = torch.device("cpu")
    ref = Reference("dataset", {"kind": "reference"}, {}, Reference.Settings(samples=5, seed=3, device="cpu"), cpu)
    gt = ContactGrasp("ours-gt-contact", {"kind": "contact_grasp", "contact": "ground_truth", "grasp": "g"},
                      {"g": torch.nn.Identity()}, ContactGrasp.Settings(samples=5, seed=3, device="cpu"), cpu)
    reordered = 0
    for row in range(shard.n_configs):
        batch = Batch.collate([data[row]], cpu).repeat(5)
        ids = ground_truth_pick(shard, row, 5, 3)
        own = gt_rows(shard, row)
        assert len(own) > 0 and set(ids) <= set(own) and len(set(ids)) == min(5, len(own))
        for draw in (0, 1):  # the methods' own streams do not change the pick
            gen, rng = torch.Generator().manual_seed(draw), np.random.default_rng(draw)
            pred = ref.predict(batch, shard, row, gen, rng)
            np.testing.assert_array_equal(pred.grasp, shard.grasp[ids].astype(np.float64))
            np.testing.assert_array_equal(pred.contact, shard.contact[ids])
            np.testing.assert_array_equal(gt.source.maps(batch, shard, row, gen).numpy(), shard.contact[ids])
        reordered += int(not np.array_equal(ground_truth_pick(shard, row, 5, 4), ids))
    assert reordered > 0  # another seed draws another order


def test_pv_voxelises_the_convex_parts_inner_faces_included_or_the_mesh(tmp_path):
    """The paper's PV voxelises the decomposed mesh (its parts side by side, inner faces kept): a cube cut
    into two overlapping halves has more surface voxels than the cube, inside it; ``pv_mesh: mesh`` takes
    the watertight mesh; another value is an error naming the setting."""
    from tohgs.assets.mesh import collision_mesh
    from tohgs.metrics.evaluate import _object_assets

    obj = tmp_path / "objects" / "cube"
    obj.mkdir(parents=True)
    cube = trimesh.creation.box(extents=(0.04, 0.04, 0.04))
    cube.export(obj / "mesh.obj")
    halves = [trimesh.creation.box(extents=(0.024, 0.04, 0.04), transform=trimesh.transformations.translation_matrix(
        [x, 0, 0])) for x in (-0.008, 0.008)]  # overlapping by 8 mm about x = 0
    lines, offset = [], 1
    for k, p in enumerate(halves):
        lines += [f"o part_{k}"] + [f"v {a} {b} {c}" for a, b, c in p.vertices]
        lines += [f"f {a + offset} {b + offset} {c + offset}" for a, b, c in p.faces]
        offset += len(p.vertices)
    (obj / "collision.obj").write_text("\n".join(lines) + "\n")
    record_object_files(obj, {"name": "cube"}, ["mesh.obj", "collision.obj"])
    assert len(collision_mesh(tmp_path / "objects", "cube").faces) == 24
    parts = _object_assets(tmp_path / "objects", "cube", 0.001, {}, pv_mesh="collision").voxels
    whole = _object_assets(tmp_path / "objects", "cube", 0.001, {}, pv_mesh="mesh").voxels
    inside = np.abs(parts).max(1) < 0.018  # voxels well inside the cube: the halves' inner faces
    assert len(parts) > len(whole) and inside.sum() > 500 and (np.abs(whole).max(1) < 0.018).sum() == 0
    with pytest.raises(ValueError, match="evaluation.pv_mesh"):
        _object_assets(tmp_path / "objects", "cube", 0.001, {}, pv_mesh="hull")


def test_a_table_shows_the_papers_printed_values_next_to_the_runs():
    rows = pd.concat([_rows([0.0], [0.0], [0.0], [0.0], method="dataset"), _rows([0.0], [0.0], [0.0], [0.0])])
    t = metric_table(rows, ["placing"], ["dataset", "ours"], LABELS, ["qr", "ts"], QualityThresholds(),
                     paper=["ts", "init_opp", "ds_per_vertex"])
    assert list(t.columns) == ["task", "method", "qr", "ts", "paper_ts", "paper_init_opp", "paper_ds_per_vertex"]
    ours = t.set_index("method").loc["Ours"]
    assert ours.paper_ts == 0.563 and ours.paper_init_opp == 6.82  # the paper's Table 1, Placing
    assert ours.paper_ds_per_vertex == pytest.approx(41.91 / 778 * 100)  # its DS over MANO's 778 vertices, cm
    assert t.set_index("method").loc["Dataset"][["paper_ts", "paper_init_opp"]].isna().all()  # not in the paper
    assert "| TS (paper) |" in markdown(t) and "| 0.563 |" in markdown(t)
    with pytest.raises(ValueError, match="no column 'ds_total'"):
        metric_table(rows, ["placing"], ["ours"], LABELS, ["qr"], QualityThresholds(), paper=["ds_total"])
