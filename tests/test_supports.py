"""Table and shelves: geometry and the JSON round trip."""

from __future__ import annotations

import pytest

from tohgs.assets.supports import make_shelf, make_table, read_supports, write_supports


def test_table_top_is_z0():
    t = make_table((1.5, 1.0, 0.05))
    m = t.mesh()
    assert m.bounds[1, 2] == pytest.approx(0.0) and m.bounds[0, 2] == pytest.approx(-0.05)
    assert m.volume == pytest.approx(1.5 * 1.0 * 0.05)
    assert t.surfaces[0].z == 0.0


def test_shelf_boards_and_clearance():
    s = make_shelf("x", width=0.8, depth=0.4, clearance=0.3, levels=3, thickness=0.02)
    m = s.mesh()
    assert m.is_watertight
    assert m.bounds[1].tolist() == pytest.approx([0.4, 0.2, 3 * 0.3 + 4 * 0.02])
    assert len(s.surfaces) == 3
    for k, surf in enumerate(s.surfaces):
        assert surf.z == pytest.approx(k * 0.32 + 0.02)
        # the board top is solid right below the surface, and free space right above it
        probe = [[0.0, 0.0, surf.z - 0.005], [0.0, 0.0, surf.z + 0.005], [0.0, 0.0, surf.z + 0.29]]
        assert m.contains(probe).tolist() == [True, False, False]
    with pytest.raises(ValueError, match="shelf 'bad'"):
        make_shelf("bad", 0.8, 0.4, 0.3, 0, 0.02)


def test_supports_round_trip(tmp_path):
    shelves = [{"name": "a", "width": 0.7, "depth": 0.35, "clearance": 0.36, "levels": 2, "thickness": 0.02}]
    written = write_supports([1.5, 1.0, 0.05], shelves, tmp_path / "supports")
    assert sorted(f.name for f in (tmp_path / "supports").iterdir()) == ["shelf-a.obj", "supports.json", "table.obj"]
    read = read_supports(tmp_path / "supports" / "supports.json")
    assert read == {s.name: s for s in written}
