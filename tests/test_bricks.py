"""The 23 generated bricks: distinct, watertight, single solids, sized for a hand, resting on z = 0."""

from __future__ import annotations

import numpy as np
import pytest

from tohgs.assets.bricks import brick_names, make_brick


def test_there_are_23_distinct_bricks():
    names = brick_names()
    assert len(names) == 23 == len(set(names))
    signatures = {tuple(np.round(np.r_[np.sort(make_brick(n).extents), make_brick(n).volume * 1e6], 2))
                  for n in names}
    assert len(signatures) == 23, "two bricks have the same extents and volume"


@pytest.mark.parametrize("name", brick_names())
def test_brick_is_a_hand_sized_solid_on_its_base(name):
    m = make_brick(name)
    assert m.is_watertight and m.is_winding_consistent
    assert m.volume > 0
    assert len(m.split(only_watertight=False)) == 1
    assert 0.025 <= m.extents.min() and m.extents.max() <= 0.11
    assert m.bounds[0, 2] == pytest.approx(0.0, abs=1e-6)


def test_scale_and_unknown_name():
    assert make_brick("cube", scale=2.0).volume == pytest.approx(8 * make_brick("cube").volume, rel=1e-5)
    with pytest.raises(KeyError, match="unknown brick 'pyramid'"):
        make_brick("pyramid")
