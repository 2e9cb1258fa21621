"""Convex decomposition: convex shortcut, CoACD on a concave brick, the cache, and a crash of CoACD."""

from __future__ import annotations

import re
import sys

import numpy as np
import pytest
import trimesh

from tohgs.assets import decomposition
from tohgs.assets.bricks import make_brick
from tohgs.assets.decomposition import DecompositionError, DecompositionSettings, cache_key, convex_decomposition

FAST = DecompositionSettings(threshold=0.2, max_convex_hull=6, preprocess_resolution=20, resolution=500,
                             mcts_iterations=20, mcts_depth=2, mcts_nodes=5)


def test_convex_mesh_is_its_own_hull(tmp_path):
    cube = make_brick("cube")
    parts, method = convex_decomposition(cube, FAST, tmp_path)
    assert method == "hull" and len(parts) == 1
    assert parts[0].volume == pytest.approx(cube.volume, rel=1e-6)
    assert not (tmp_path / "coacd").exists()


def test_concave_mesh_is_decomposed_and_cached(tmp_path):
    l_brick = make_brick("l-shape")
    parts, method = convex_decomposition(l_brick, FAST, tmp_path)
    assert method == "coacd" and len(parts) >= 2
    for p in parts:
        assert p.is_convex and p.volume > 0
    # The parts cover the shape: total volume close to the brick's, and no part far outside it.
    assert sum(p.volume for p in parts) == pytest.approx(l_brick.volume, rel=0.15)
    assert np.all(np.ptp(np.concatenate([p.bounds for p in parts]), axis=0) <= l_brick.extents * 1.05)
    cached, method2 = convex_decomposition(l_brick, FAST, tmp_path)
    assert method2 == "coacd-cached"
    assert [len(p.vertices) for p in cached] == [len(p.vertices) for p in parts]
    np.testing.assert_allclose(cached[0].vertices, parts[0].vertices)


def test_cache_key_changes_with_settings_and_geometry():
    m = make_brick("l-shape")
    k = cache_key(m, FAST)
    assert k == cache_key(m, FAST)
    assert k != cache_key(m, DecompositionSettings(**{**FAST.__dict__, "threshold": 0.3}))
    assert k != cache_key(make_brick("l-shape", scale=1.1), FAST)


def test_hull_vertex_cap_keeps_a_close_inner_hull():
    from tohgs.assets.decomposition import cap_hull_vertices

    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.05)  # 2562 vertices
    capped = cap_hull_vertices(sphere, 64)
    assert len(capped.vertices) <= 64 and capped.is_convex
    assert 0.8 * sphere.volume < capped.volume <= sphere.volume + 1e-12
    assert cap_hull_vertices(capped, 64) is capped  # already small enough: unchanged


@pytest.mark.parametrize("child, expected", [
    ("import os; os.abort()", "killed by SIGABRT"),
    ("import sys; sys.exit('bad mesh')", "exited with status 1 on this mesh (bad mesh)"),
])
def test_a_crash_of_coacd_is_an_error_of_the_mesh_not_of_the_process(tmp_path, monkeypatch, child, expected):
    # CoACD aborts the process on some meshes (a failed C++ assertion); its child stands in for it here.
    monkeypatch.setattr(decomposition, "WORKER", [sys.executable, "-c", child])
    with pytest.raises(DecompositionError, match=re.escape(expected)):
        convex_decomposition(make_brick("l-shape"), FAST, tmp_path)
    assert not list(tmp_path.rglob("*.npz")), "a crash left parts in the cache"
    # A convex mesh never reaches CoACD, so the crash cannot reach it either.
    assert convex_decomposition(make_brick("cube"), FAST, tmp_path)[1] == "hull"
