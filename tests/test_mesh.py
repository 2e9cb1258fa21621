"""Mesh loading, repair and validation, scaling and mass properties on cases with known answers."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from tohgs.assets.mesh import MeshError, choose_scale, load_mesh, mass_properties, normalise, repair_and_validate


def test_missing_file_names_the_path(tmp_path):
    with pytest.raises(MeshError, match="nothing.obj: file not found"):
        load_mesh(tmp_path / "nothing.obj")


def test_garbage_file_is_an_error_naming_it(tmp_path):
    bad = tmp_path / "broken.stl"
    bad.write_bytes(b"\x00\x01 not a mesh at all")
    with pytest.raises(MeshError, match="broken.stl"):
        load_mesh(bad)


def test_non_finite_vertices_rejected():
    box = trimesh.creation.box()
    v = box.vertices.copy()
    v[0, 0] = np.nan
    with pytest.raises(MeshError, match="non-finite"):
        repair_and_validate(trimesh.Trimesh(v, box.faces, process=False))


def test_hole_is_filled():
    box = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    holed = trimesh.Trimesh(box.vertices, box.faces[1:], process=False)
    assert not holed.is_watertight
    fixed, repairs = repair_and_validate(holed)
    assert fixed.is_watertight and "filled holes" in repairs
    assert fixed.volume == pytest.approx(1e-3, rel=1e-6)


def test_inverted_mesh_gets_positive_volume():
    box = trimesh.creation.box(extents=(0.1, 0.2, 0.3))
    inv = trimesh.Trimesh(box.vertices, box.faces[:, ::-1], process=False)
    fixed, repairs = repair_and_validate(inv)
    assert fixed.volume == pytest.approx(0.006, rel=1e-6)
    assert repairs


def test_touching_bodies_are_fused_into_one_solid():
    """Pieces that touch face to face (as in pybullet_data's random_urdfs) make one solid."""
    a = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    b = trimesh.creation.box(extents=(0.1, 0.06, 0.06))
    b.apply_translation((0.1, 0.0, 0.0))  # its face x = 0.05 lies on a's face
    fixed, repairs = repair_and_validate(trimesh.util.concatenate([a, b]))
    assert len(fixed.split(only_watertight=False)) == 1
    assert fixed.volume == pytest.approx(1.36e-3, rel=0.01)
    assert any("fused 2 bodies" in r for r in repairs)


def test_a_random_urdfs_object_is_repaired_into_one_solid():
    from tohgs.assets.sources import pybullet_random_candidates

    raw = load_mesh(pybullet_random_candidates()[0].path)
    assert len(raw.split(only_watertight=False)) > 1
    fixed, repairs = repair_and_validate(raw)
    assert fixed.is_volume and len(fixed.split(only_watertight=False)) == 1
    assert repairs


def test_stray_open_fragment_is_dropped():
    """A scanned mesh's isolated single triangle (the YCB meshes carry some) is dropped, not a rejection."""
    box = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    stray = trimesh.Trimesh([[0.2, 0, 0], [0.2001, 0, 0], [0.2, 0.0001, 0]], [[0, 1, 2]], process=False)
    fixed, repairs = repair_and_validate(trimesh.util.concatenate([box, stray]))
    assert len(fixed.split(only_watertight=False)) == 1
    assert fixed.volume == pytest.approx(1e-3, rel=1e-6)
    assert any(r.startswith("dropped 1 stray open fragment") for r in repairs)
    assert not any("fused" in r for r in repairs)


def test_stray_fragment_dropped_before_touching_bodies_are_fused():
    a = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    b = trimesh.creation.box(extents=(0.1, 0.06, 0.06))
    b.apply_translation((0.1, 0.0, 0.0))
    stray = trimesh.Trimesh([[0.4, 0, 0], [0.4001, 0, 0], [0.4, 0.0001, 0]], [[0, 1, 2]], process=False)
    fixed, repairs = repair_and_validate(trimesh.util.concatenate([a, b, stray]))
    assert fixed.volume == pytest.approx(1.36e-3, rel=0.01)
    assert any("stray" in r for r in repairs) and "fused 2 bodies" in repairs


def test_large_open_body_beside_a_solid_is_still_rejected():
    """Only fragments below STRAY_AREA_FRACTION of the surface are dropped: an open sheet as large as a
    face of the box rejects the mesh."""
    box = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    sheet = trimesh.Trimesh([[0.3, 0, 0], [0.4, 0, 0], [0.3, 0.1, 0], [0.4, 0.1, 0]], [[0, 1, 2], [1, 3, 2]],
                            process=False)
    with pytest.raises(MeshError, match="not watertight; cannot fuse"):
        repair_and_validate(trimesh.util.concatenate([box, sheet]))


def test_separate_bodies_are_rejected():
    a = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    b = a.copy()
    b.apply_translation((0.3, 0.0, 0.0))
    with pytest.raises(MeshError, match="disconnected"):
        repair_and_validate(trimesh.util.concatenate([a, b]))


def test_open_sheet_is_rejected():
    sheet = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], [[0, 1, 2], [1, 3, 2]], process=False)
    with pytest.raises(MeshError):
        repair_and_validate(sheet)


def test_choose_scale_respects_both_ranges():
    rng = np.random.default_rng(0)
    ext = np.array([3.0, 1.0, 2.0])
    for _ in range(200):
        s = choose_scale(ext, (0.08, 0.16), (0.012, 0.08), rng)
        assert 0.08 - 1e-12 <= s * 3.0 <= 0.16 + 1e-12
        assert 0.012 - 1e-12 <= s * 1.0 <= 0.08 + 1e-12


def test_choose_scale_rejects_impossible_aspect_ratio():
    with pytest.raises(MeshError, match="aspect ratio"):
        choose_scale(np.array([100.0, 1.0, 1.0]), (0.08, 0.16), (0.012, 0.08), np.random.default_rng(0))


def test_normalise_centres_the_centre_of_mass_and_scales():
    m = trimesh.creation.box(extents=(2.0, 1.0, 1.0))
    m.apply_translation((5.0, -3.0, 1.0))
    out = normalise(m, 0.05)
    np.testing.assert_allclose(out.center_mass, 0.0, atol=1e-12)
    np.testing.assert_allclose(out.extents, (0.1, 0.05, 0.05), rtol=1e-12)


def test_mass_properties_of_a_box():
    m = trimesh.creation.box(extents=(0.1, 0.2, 0.3))
    mp = mass_properties(m, 1000.0)
    assert mp.mass == pytest.approx(6.0)
    # solid box: I_xx = m (b^2 + c^2) / 12
    assert mp.inertia[0, 0] == pytest.approx(6.0 * (0.2**2 + 0.3**2) / 12)
