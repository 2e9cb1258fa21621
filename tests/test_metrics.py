"""Grasp quality metrics on cases with known answers."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from tohgs.metrics.quality import (DisplacementSimulator, SDSettings, contact_distance, penetration_volume,
                                   surface_voxels)


@pytest.fixture(scope="module")
def cube(tmp_path_factory):
    """A 4 cm cube centred at the origin, its collision file and surface voxels."""
    mesh = trimesh.creation.box(extents=(0.04, 0.04, 0.04))
    path = tmp_path_factory.mktemp("cube") / "collision.obj"
    mesh.export(path)
    return mesh, path, surface_voxels(mesh)


def _slab(z_top: float) -> trimesh.Trimesh:
    """A 'hand' stand-in: a closed 10 x 10 x 2 cm slab whose top face is at ``z_top``."""
    slab = trimesh.creation.box(extents=(0.1, 0.1, 0.02))
    slab.apply_translation((0, 0, z_top - 0.01))
    return slab


def test_surface_voxels_cover_the_surface_only(cube):
    _, _, vox = cube
    # 6 faces of 4 x 4 cm at 1 mm: about 6 * 40 * 40 voxels on the shell, none deep inside.
    assert 6 * 38 * 38 < len(vox) < 6 * 42 * 42
    assert np.abs(vox).max(1).min() > 0.018


def test_surface_voxels_cache_returns_the_same_voxels_and_heals(cube, tmp_path, caplog):
    mesh, _, vox = cube
    first = surface_voxels(mesh, cache_dir=tmp_path)
    (entry,) = (tmp_path / "voxels").glob("*.npy")
    np.testing.assert_array_equal(first, vox)
    np.testing.assert_array_equal(surface_voxels(mesh, cache_dir=tmp_path), vox)  # read back
    assert len(list((tmp_path / "voxels").glob("*.npy"))) == 1
    surface_voxels(mesh, pitch=0.002, cache_dir=tmp_path)  # another pitch, another entry
    assert len(list((tmp_path / "voxels").glob("*.npy"))) == 2
    entry.write_bytes(b"damaged")
    np.testing.assert_array_equal(surface_voxels(mesh, cache_dir=tmp_path), vox)
    assert entry.name in caplog.text  # the damaged entry is reported, not silently replaced
    np.testing.assert_array_equal(np.load(entry), vox)  # replaced


def test_pv_is_zero_clear_of_the_object_and_grows_as_the_hand_sinks_in(cube):
    mesh, _, vox = cube
    slab_depths = [-0.005, 0.0005, 0.003, 0.008, 0.015]  # how far the slab's top rises above the cube's bottom
    pv = [penetration_volume(_slab(-0.02 + d).vertices, _slab(-0.02 + d).faces, vox) for d in slab_depths]
    assert pv[0] == 0.0
    assert all(b > a for a, b in zip(pv[1:], pv[2:])), pv
    # Sunk 8 mm: the bottom face (40 x 40 voxels) plus 4 side strips of about 8 mm x 40 mm.
    expect = (40 * 40 + 4 * 8 * 40) * 1e-9
    assert pv[3] == pytest.approx(expect, rel=0.15)
    both = penetration_volume(np.stack([_slab(-0.025).vertices, _slab(-0.012).vertices]), _slab(0).faces, vox)
    assert both[0] == 0.0 and both[1] > 0


def test_contact_distance_is_signed(cube):
    """Measured from the hand's vertices: a densely meshed slab 5 mm under the cube, then 5 mm into it."""
    mesh, _, _ = cube
    below = _slab(-0.025).subdivide_to_size(0.002)
    assert contact_distance(below.vertices, mesh) == pytest.approx(0.005, abs=2e-4)
    assert contact_distance(_slab(-0.015).subdivide_to_size(0.002).vertices, mesh) == pytest.approx(-0.005, abs=2e-4)
    assert contact_distance(_slab(-0.025).vertices, mesh) > 0.04  # only the 8 corners of a coarse slab


def test_an_object_falling_free_for_35_steps_moves_10_7_cm(cube):
    mesh, path, _ = cube
    far = _slab(-0.5)
    with DisplacementSimulator(path, mesh.vertices.mean(0)) as sim:
        sd = sim.displacement(far.vertices, far.faces)
    # Semi-implicit Euler: g dt^2 n (n + 1) / 2 = 9.8 / 240^2 * 35 * 36 / 2 = 0.1072 m.
    assert sd == pytest.approx(9.8 / 240**2 * 35 * 36 / 2, rel=0.01)


def test_an_object_held_in_a_closed_static_cup_moves_less_than_a_millimetre(cube):
    mesh, path, _ = cube
    outer = trimesh.creation.box(extents=(0.06, 0.06, 0.06))
    inner = trimesh.creation.box(extents=(0.0405, 0.0405, 0.0405))
    inner.apply_translation((0, 0, 0.00025))  # 0.25 mm below the cube's bottom face is the cup's floor
    inner.invert()
    cup = trimesh.util.concatenate([outer, inner])  # a closed box with a cube-shaped cavity
    with DisplacementSimulator(path, mesh.vertices.mean(0)) as sim:
        sd = sim.displacement(cup.vertices, cup.faces)
    assert sd < 0.001


def test_gravity_direction_is_a_setting(cube):
    mesh, path, _ = cube
    floor = _slab(-0.02)  # a floor right under the cube: with gravity along -z it stays, along +x it slides
    with DisplacementSimulator(path, mesh.vertices.mean(0)) as sim:
        assert sim.displacement(floor.vertices, floor.faces) < 0.002
    with DisplacementSimulator(path, mesh.vertices.mean(0), SDSettings(gravity=(9.8, 0.0, 0.0))) as sim:
        assert sim.displacement(floor.vertices, floor.faces) > 0.05


def test_palm_gravity_points_from_the_palm_through_the_object():
    from tohgs.metrics.quality import palm_gravity

    g = palm_gravity(np.array([[0.0, 0.0, 0.1], [0.05, 0.0, 0.0]]), np.zeros(3))
    np.testing.assert_allclose(g, [[0, 0, -9.8], [-9.8, 0, 0]])
