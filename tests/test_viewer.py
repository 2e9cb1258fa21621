"""The 3D viewer (tohgs.viz.view) on a finished smoke run: what it reads (through the store layer), the
command's start, errors and stop, the page in headless Chromium (a scene on the canvas, a picture that
changes with the method and the configuration, nothing fetched beyond loopback) and the static export.

The smoke run is the session's (tests/conftest.py), or a finished run's ``results/`` folder named by
``TOHGS_SMOKE_RESULTS`` (to run these tests alone). The browser tests need Debian's chromium (``make test``
installs it as root) and skip without it, saying so.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import viewer_browser as vb

pytest.importorskip("viser", reason="the viewer extra is not installed (pip install -e '.[viewer]')")

from tohgs.viz.view import camera_for, map_colors, method_colors  # noqa: E402
from tohgs.viz.view_data import GROUND_TRUTH, NO_MAP, TaskResults, available_tasks  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
needs_chromium = pytest.mark.skipif(vb.chromium() is None, reason="no chromium (Debian's package): the viewer's "
                                    "browser tests need it; make test installs it as root (apt-get install chromium)")


@pytest.fixture(scope="module")
def results(request) -> Path:
    given = os.environ.get("TOHGS_SMOKE_RESULTS")
    if given:
        return Path(given)
    return request.getfixturevalue("smoke_run") / "results"


@pytest.fixture(scope="module")
def placing(results) -> TaskResults:
    return TaskResults.from_results(results, "placing")


# -- without a browser ------------------------------------------------------------------------------------------

def test_method_colours_are_distinct_and_stable_across_tasks():
    order = ["dataset", "ours", "grasptta", "flex"]
    a = method_colors(["ours", "flex"], order)
    b = method_colors(["dataset", "ours", "grasptta", "flex", "ours-s1"], order)
    assert a["ours"] == b["ours"] and a["flex"] == b["flex"]
    assert len({rgb for _, rgb in b.values()}) == len(b)
    assert b["dataset"][0] == "skin"
    assert map_colors(np.array([0.0, 1.0]), GROUND_TRUTH).shape == (2, 3)
    assert not np.array_equal(*map_colors(np.array([0.0, 1.0]), GROUND_TRUTH))


def test_the_camera_looks_at_the_target_from_the_open_side():
    eye, look = camera_for("shelving", [np.array([0.2, 0.3, 0.5])])
    assert np.allclose(look, [0.2, 0.3, 0.5]) and eye[1] < look[1]  # from the open front (-y)
    eye, look = camera_for("placing", [np.zeros(3), np.array([1.0, 0.0, 0.0])])
    assert np.allclose(look, [0.5, 0, 0]) and np.linalg.norm(eye - look) >= 1.4 - 1e-9  # both targets in view (1.4 x their spread, rounded)


def test_a_large_mesh_is_decimated_once_for_the_export_and_keeps_its_shape():
    import trimesh

    from tohgs.viz.view import decimated

    sphere = trimesh.creation.icosphere(subdivisions=4)  # 5120 faces
    cache: dict = {}
    small = decimated(sphere, 1000, cache)
    assert len(small.faces) <= 1000 and np.allclose(small.bounds, sphere.bounds, atol=0.05)
    assert decimated(sphere, 1000, cache) is small and decimated(sphere, 10_000) is sphere


@pytest.mark.slow
def test_the_cloud_lies_on_the_target_at_both_poses_and_the_maps_are_the_stores(placing):
    import trimesh

    obj, c = placing.configurations[0]
    for pose in ("init", "goal"):
        pts, nrm = placing.cloud(obj, c, pose)
        mesh = placing.target(obj, c, pose)
        _, dist, _ = trimesh.proximity.closest_point(mesh, pts)
        assert dist.max() < 2e-3, (pose, dist.max())  # the shard's surface samples, moved into the world
        assert np.allclose(np.linalg.norm(nrm, axis=1), 1, atol=1e-3)
    names = placing.map_names()
    assert names[0] == GROUND_TRUTH and names[-1] == NO_MAP and len(names) == 4 + len(placing.methods)
    ours = next(m for m in placing.methods.values() if m.name == "ours")
    i = ours.rows[(obj, c)]
    assert np.array_equal(placing.map_values(obj, c, f"contact: {ours.label}", 1), ours.arrays["contact"][i, 1])
    assert placing.map_values(obj, c, NO_MAP, 0) is None


@pytest.mark.slow
def test_every_method_has_a_hand_at_both_poses_with_its_metric_row(placing, results):
    import pandas as pd

    obj, c = placing.configurations[0]
    hands = placing.hands(obj, c, 0)
    assert [h.method for h in hands] == [m for m in placing.methods if (obj, c) in placing.methods[m].rows]
    for h in hands:
        assert h.vertices["init"].shape == h.vertices["goal"].shape == (len(placing.hand.rest_vertices), 3)
        rows = pd.read_parquet(results / "metrics/placing" / f"{h.method}.parquet")
        row = rows[(rows.object == obj) & (rows.config_index == c) & (rows["sample"] == 0)].iloc[0]
        if h.kept:
            assert h.metrics["pv"] == pytest.approx(row.pv) and h.metrics["goal_opp"] == pytest.approx(row.goal_opp)
            assert h.quality == bool(row.pv < 3e-6 and row.sd < 0.02)
            assert "QR" in h.summary()
    # the goal hand is the initial hand carried by the target's motion: the same shape, moved
    h = hands[0]
    d_init = np.linalg.norm(h.vertices["init"] - h.vertices["init"][0], axis=1)
    d_goal = np.linalg.norm(h.vertices["goal"] - h.vertices["goal"][0], axis=1)
    assert np.allclose(d_init, d_goal, atol=1e-4)


@pytest.mark.slow
def test_a_skinned_hand_is_posed_like_its_vertices(placing):
    """The joint frames a static export sends, applied as three.js skins a mesh (linear blend skinning from
    the bind pose: the rest joints, unrotated), give the hand's vertices."""
    import viser
    from scipy.spatial.transform import Rotation

    from tohgs.viz.view import add_hand

    hand = placing.hand
    obj, c = placing.configurations[0]
    grasp = placing.hands(obj, c, 0)[0].grasps["goal"]
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        handle = add_hand(server.scene, "/hand", hand, grasp, (255, 0, 0), skinned=True)
        frames = [(np.asarray(b.wxyz), np.asarray(b.position)) for b in handle.bones]
    finally:
        server.stop()
    joints = np.asarray(hand.rest_joints)
    skin = np.zeros((len(hand.rest_vertices), 3))
    for j, (wxyz, pos) in enumerate(frames):
        R = Rotation.from_quat([wxyz[1], wxyz[2], wxyz[3], wxyz[0]]).as_matrix()
        skin += hand.weights[:, j:j + 1] * ((hand.rest_vertices - joints[j]) @ R.T + pos)
    want = hand.vertices(grasp[None])[0]
    assert np.abs(skin - want).max() < 1e-5
    assert np.abs(want - hand.vertices(placing.hands(obj, c, 0)[0].grasps["init"][None])[0]).max() > 1e-3


def _partial_results(results: Path, dest: Path, damaged: str | None = None) -> Path:
    """A results folder of links to ``results``' parts, with a copy of the prediction store ``damaged`` of
    placing (if given) whose grasps' chunk is cut short."""
    dest.mkdir(parents=True)
    for part in ("objects", "hand", "scenes", "maps", "metrics"):
        (dest / part).symlink_to((results / part).resolve())
    (dest / "predictions").mkdir()
    (dest / "predictions/placing").mkdir()
    for store in (results / "predictions/placing").glob("*.zarr"):
        if store.stem == damaged:
            shutil.copytree(store, dest / "predictions/placing" / store.name)
            chunk = next(p for p in (dest / "predictions/placing" / store.name / "grasp_init").rglob("*")
                         if p.is_file() and p.name != "zarr.json")
            chunk.write_bytes(chunk.read_bytes()[: chunk.stat().st_size // 2])
        else:
            (dest / "predictions/placing" / store.name).symlink_to(store.resolve())
    return dest


@pytest.mark.slow
def test_a_damaged_or_missing_store_gets_the_store_layers_message(results, tmp_path):
    bad = _partial_results(results, tmp_path / "bad", damaged="ours")
    with pytest.raises(ValueError, match=r"predictions/placing/ours\.zarr: array 'grasp_init'"):
        TaskResults.from_results(bad, "placing")
    with pytest.raises(ValueError, match="no prediction stores of task 'stacking'"):
        TaskResults.from_results(bad, "stacking")
    with pytest.raises(ValueError, match="results folder not found"):
        available_tasks(tmp_path / "nowhere")
    shutil.rmtree(tmp_path / "bad/predictions/placing/ours.zarr")
    (tmp_path / "bad/scenes").unlink()
    (tmp_path / "bad/scenes").mkdir()
    with pytest.raises(ValueError, match=r"scenes/placing/.*\.zarr: scene store not found"):
        TaskResults.from_results(bad, "placing")
    # the command says the same, and exits 1 without a traceback
    out = subprocess.run([sys.executable, "-m", "tohgs.viz.view", str(bad), "--task", "placing", "--port", "0"],
                         capture_output=True, text=True, timeout=120, env=_env())
    assert out.returncode == 1 and "scene store not found" in out.stderr and "Traceback" not in out.stderr


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}


@pytest.mark.slow
def test_the_viewer_serves_on_loopback_and_stops_by_itself(results):
    proc, url, seconds = vb.start_viewer(results, "placing", stop_after=2)
    try:
        assert url.startswith("http://127.0.0.1:")
        port = int(url.rsplit(":", 1)[1])
        with socket.create_connection(("127.0.0.1", port), timeout=5):
            pass
        assert proc.wait(60) == 0  # --stop-after: the server stops by itself
    finally:
        proc.kill()
    print(f"\nviewer ready in {seconds:.1f} s (python start, imports, the task's stores)")
    with pytest.raises(OSError):
        socket.create_connection(("127.0.0.1", port), timeout=5).close()


# -- in headless Chromium -----------------------------------------------------------------------------------

@pytest.mark.slow
@needs_chromium
def test_the_viewer_shows_the_scene_and_the_picture_follows_the_controls(results, tmp_path):
    data = TaskResults.from_results(results, "placing")
    first = next(iter(data.methods.values()))
    proc, url, seconds = vb.start_viewer(results, "placing", stop_after=300)
    requests: list[str] = []
    try:
        with vb.browser() as ctx:
            page = vb.open_page(ctx, url, requests)
            start = vb.wait_for_scene(page)
            vb.save(start, tmp_path / "start.png")
            assert vb.scene_fraction(start) > 0.05, "the canvas shows no scene"
            assert start.std() > 10
            # hiding the first method takes its hands (and its label) out of the picture
            page.get_by_label(f"{first.label} (").first.click()
            hidden = vb.wait_for_change(page, start)
            vb.save(hidden, tmp_path / "method_hidden.png")
            assert vb.changed(hidden, start) > 0.002, "hiding a method did not change the picture"
            # another configuration (of another object where there is one) moves the camera to its target
            if len(data.objects) > 1:
                page.get_by_label("Object").click()
                page.get_by_role("option", name=data.objects[1]).click()
            else:
                page.get_by_label("Configuration").click()
                page.get_by_role("option", name=str(data.configs_of(data.objects[0])[1])).click()
            other = vb.wait_for_change(page, hidden)
            vb.save(other, tmp_path / "other_config.png")
            assert vb.changed(other, hidden) > 0.05, "another configuration did not change the picture"
            assert vb.scene_fraction(other) > 0.05
    finally:
        proc.terminate()
        proc.wait(30)
    assert not vb.outside(requests), f"the page fetched beyond loopback: {vb.outside(requests)[:5]}"
    print(f"\nviewer ready in {seconds:.1f} s; screenshots in {tmp_path}")


@pytest.mark.slow
@needs_chromium
def test_the_static_export_renders_offline_in_chromium(results, tmp_path):
    from tohgs.viz.view import REPORT_BYTES, YCB_CREDIT, export_html

    html = results / "viewer/placing.html"  # the workflow's (rule viewer, in the default target)
    if "TOHGS_SMOKE_RESULTS" not in os.environ:
        assert html.is_file(), "the smoke run wrote no results/viewer/placing.html"
    elif not html.exists():  # a run of before the rule: written here
        html = tmp_path / "placing.html"
        export_html(TaskResults.from_results(results, "placing"), html)
    text = html.read_text()
    assert "__VISER_EMBED_DATA__" in text and 100_000 < len(text) < 30_000_000
    assert len(text) < REPORT_BYTES, "over what the report's frame shows"
    data = TaskResults.from_results(results, "placing")
    if any(o.startswith("ycb-") for o in data.objects) and len(data.objects) <= 4:  # every object drawn
        assert YCB_CREDIT in text, "a page with YCB models carries their credit (CC BY 4.0)"
    requests: list[str] = []
    with vb.browser() as ctx:
        page = vb.open_page(ctx, html.resolve().as_uri(), requests)
        shot = vb.wait_for_scene(page)
        vb.save(shot, tmp_path / "static.png")
        assert vb.scene_fraction(shot) > 0.05, "the static export shows no scene"
        assert requests and not vb.outside(requests), f"the export fetched: {vb.outside(requests)[:5]}"
        # its skinned hands draw what the hands' vertices draw (one configuration, the first method)
        shots = []
        for skinned in (True, False):
            one = tmp_path / f"one_{skinned}.html"
            export_html(data, one, configs=1, methods=list(data.methods)[:1], skinned=skinned)
            page.close()
            page = vb.open_page(ctx, one.resolve().as_uri(), [])
            shots.append(vb.wait_for_scene(page))
            vb.save(shots[-1], tmp_path / f"one_{skinned}.png")
    assert vb.changed(*shots) < 0.01, "the skinned hands are not where their vertices are"
