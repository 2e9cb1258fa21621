"""benchmarks/frame_axes.py: the circular statistics it reports, and that its measures are those of the frame,
whatever way the input is turned."""

import math

import numpy as np
import torch

from helpers import load_benchmark
from tohgs.data.batch import Batch
from tohgs.data.maps import MapDataset

frame_axes = load_benchmark("frame_axes")


def test_the_resultants_tell_a_direction_from_a_line_and_from_no_direction():
    g = torch.Generator().manual_seed(0)
    n = 2000
    normal = torch.tensor([[0.0, 0.0, 1.0]]).expand(n, 3)
    axis = torch.tensor([[1.0, 0.0, 0.0]]).expand(n, 3)
    at_30 = torch.tensor([[math.cos(0.5), math.sin(0.5), 0.3]]).expand(n, 3)  # 0.5 rad from the axis, off the plane
    angle = frame_axes.signed_angle(axis, at_30, normal)
    assert torch.allclose(angle, torch.full((n,), 0.5, dtype=angle.dtype), atol=1e-6)
    assert frame_axes.resultant(angle, 1) > 0.999 and frame_axes.resultant(angle, 2) > 0.999
    flipped = torch.where(torch.rand(n, 1, generator=g) < 0.5, -at_30, at_30)  # the same line, either way
    angle = frame_axes.signed_angle(axis, flipped, normal)
    assert frame_axes.resultant(angle, 2) > 0.999 and frame_axes.resultant(angle, 1) < 0.1
    spread = torch.randn(n, 3, generator=g)
    angle = frame_axes.signed_angle(axis, spread, normal)
    assert frame_axes.resultant(angle, 2) < 0.1 and frame_axes.resultant(angle, 1) < 0.1
    assert frame_axes.signed_angle(axis[:1], torch.tensor([[0.0, 1.0, 0.0]]), normal[:1]).item() > 0  # counter-clockwise


def test_the_measures_are_the_frames_whatever_way_the_input_is_turned(built):
    """Everything is measured in the canonical frame of the object and its map, so turning the input (points,
    normals and the hand with them) leaves every number as it was; a measure taken in the input's
    coordinates would not."""
    folder, hand, *_ = built
    plain = MapDataset([folder / "shard-0.zarr"], per="grasp")
    turned = MapDataset([folder / "shard-0.zarr"], per="grasp", rotation="so3", seed=3)
    assert len(plain) >= 2
    a = frame_axes.frame_axes(hand, Batch.collate([plain[i] for i in range(len(plain))]), 2.0, "centroid")
    b = frame_axes.frame_axes(hand, Batch.collate([turned.item(i, 5) for i in range(len(turned))]), 2.0, "centroid")
    assert not np.allclose(turned.item(0, 5)["points"], plain[0]["points"], atol=1e-3)  # the input did turn
    assert a["grasps"] == b["grasps"] == len(plain)
    for name, row in a["axes"].items():
        for key, value in row.items():
            assert abs(value - b["axes"][name][key]) < 1e-4, (name, key, value, b["axes"][name][key])
            assert 0.0 <= value <= 1.0 + 1e-9
    for key in ("thumb_on_plus_y_pct", "palm_normal_cos_minus_x_median", "palm_from_origin_cm_median",
                "palm_offset_cos_x_median"):
        assert abs(a[key] - b[key]) < 1e-3, (key, a[key], b[key])
    assert a["palm_from_origin_cm_median"] > 0.5  # the palm is not at the contact centroid (inside the cube)
