"""Does any axis of an object and its contact map give the hand's direction? On a finished run's map shards.

The GraspDiffuser reads its input in a canonical frame of the object and the contact map
(:func:`tohgs.geometry.frames.contact_frame_3d`: x from the object towards the contact, y the contact
region's principal direction normal to x). A third of its hands come out turned about the palm's normal
from the grasp of the map they were drawn from (``benchmarks/map_fidelity.py``): the frame's x carries the
palm's side, not the direction the fingers point in the plane normal to it. This asks whether another axis
built from the same inputs, as the issue's frame averaging suggests (principal directions of the object,
of its contact region, of the contact region's normals), would carry that direction, so that a frame built
on it could. Per task and split, over every task grasp of the shards (its own ground-truth map):

- the hand's directions in the plane normal to the frame's x: from the palm centre to the mean of the four
  fingers' vertices (``fingers``) and to the mean of the thumb's (``thumb``);
- per candidate axis (a line in that plane), the resultant length of the doubled angle between it and each
  direction (axial concentration: 1 where the direction lies along the line, either way; about
  ``sqrt(pi / 4 n)`` for n directions spread evenly), and of the angle itself once the axis is signed as the
  frame signs its y (the contact region's weighted third moment along it positive; the object's own for
  the object's axis): how well the axis with that sign gives the direction, a half turn included; and the
  share of thumbs on the + side of the frame's y;
- where the palm is in the frame: the median cosine of the palm's normal (towards the object) with -x, the
  palm centre's median distance from the frame's origin (cm) and the median cosine of that offset with x.

    python benchmarks/frame_axes.py --results results --tasks placing stacking shelving \\
        [--out benchmarks/results/frame_axes.json]

A few seconds per task (the frame of every grasp's map, one forward pass of the hand).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from base_commit import commit_label, cpu_name  # noqa: E402

from tohgs.data.batch import Batch  # noqa: E402
from tohgs.data.maps import MapDataset  # noqa: E402
from tohgs.geometry.frames import contact_frame_3d  # noqa: E402
from tohgs.hand import HandAssets, HandModel  # noqa: E402
from tohgs.hand.rotations import axis_angle_to_matrix  # noqa: E402
from tohgs.io import write_json  # noqa: E402

THUMB_PARTS = (13, 14, 15)  # MANO's joint order: 1-12 the four fingers, 13-15 the thumb


def in_plane(v: torch.Tensor, normal: torch.Tensor) -> torch.Tensor:
    """(B, 3) unit ``v`` less its component along the unit (B, 3) ``normal``."""
    v = v - (v * normal).sum(-1, keepdim=True) * normal
    return v / v.norm(dim=-1, keepdim=True).clamp_min(1e-12)


def signed_angle(axis: torch.Tensor, direction: torch.Tensor, normal: torch.Tensor) -> torch.Tensor:
    """(B,) the angle (rad) from each (B, 3) ``axis`` to ``direction``, both in the plane normal to the unit
    ``normal``, positive counter-clockwise about it."""
    a, d = in_plane(axis, normal), in_plane(direction, normal)
    return torch.atan2((torch.cross(a, d, dim=-1) * normal).sum(-1), (a * d).sum(-1))


def resultant(angles: torch.Tensor, order: int = 1) -> float:
    """The mean resultant length of ``order`` x the (B,) ``angles``: 1 where they all agree (order 2: up to a
    half turn), near 0 where they are spread evenly."""
    a = order * angles.double()
    return float(torch.hypot(torch.cos(a).mean(), torch.sin(a).mean()))


def principal_in_plane(vectors: torch.Tensor, weights: torch.Tensor, normal: torch.Tensor) -> torch.Tensor:
    """(B, 3) the principal direction of the (B, N, 3) ``vectors`` about their weighted mean, weighted by the
    (B, N) ``weights``, in the plane normal to the unit (B, 3) ``normal`` (a line: its sign is arbitrary)."""
    w = weights / weights.sum(-1, keepdim=True).clamp_min(1e-12)
    centred = vectors - (w[..., None] * vectors).sum(1, keepdim=True)
    proj = centred - (centred * normal[:, None]).sum(-1, keepdim=True) * normal[:, None]
    cov = torch.einsum("bn,bni,bnj->bij", w, proj, proj)
    return in_plane(torch.linalg.eigh(cov)[1][..., 2], normal)


def signed_by_skew(axis: torch.Tensor, points: torch.Tensor, weights: torch.Tensor, at: torch.Tensor) -> torch.Tensor:
    """(B, 3) ``axis`` turned where the ``weights``' (B, N) third moment of the (B, N, 3) ``points`` about
    ``at`` (B, 3) along it is negative (the frame's sign rule for its y)."""
    w = weights / weights.sum(-1, keepdim=True).clamp_min(1e-12)
    skew = (w * (((points - at[:, None]) * axis[:, None]).sum(-1)) ** 3).sum(-1)
    return torch.where(skew[:, None] < 0, -axis, axis)


def frame_axes(hand: HandModel, batch: Batch, power: float, origin: str) -> dict:
    """The module docstring's measures for the task grasps of ``batch`` (their own maps)."""
    points, normals = batch.points.double(), batch.normals.double()
    contact = batch.contact.double().clamp_min(0)
    with torch.no_grad():
        vertices = hand(batch.grasp).vertices.double()
    labels = torch.as_tensor(hand.assets.part_labels)
    palm_ids = torch.as_tensor(hand.assets.palm_ids)
    palm = vertices[:, palm_ids].mean(1)
    thumb = torch.isin(labels, torch.as_tensor(THUMB_PARTS))
    directions = {"fingers": vertices[:, (labels > 0) & ~thumb].mean(1) - palm,
                  "thumb": vertices[:, thumb].mean(1) - palm}
    rotation, at = contact_frame_3d(points, normals, contact, power, origin)
    x, y = rotation[..., 0], rotation[..., 1]
    w = contact ** power
    ones = torch.ones_like(contact)
    core = (contact > 0.5).double() + 1e-9
    candidates = {  # name: (axis, the weights its sign is taken by)
        "frame_y": (y, w),
        "contact_region": (principal_in_plane(points, w, x), w),
        "contact_core": (principal_in_plane(points, core, x), core),
        "object": (principal_in_plane(points, ones, x), ones),
        "contact_normals": (principal_in_plane(normals, w, x), w),
    }
    n = batch.size
    out: dict = {"grasps": n, "uniform_axial_resultant": float(np.sqrt(np.pi / (4 * n))), "axes": {}}
    for name, (axis, sign_weights) in candidates.items():
        axis = axis if name == "frame_y" else signed_by_skew(axis, points, sign_weights, at if name != "object" else points.mean(1))
        row = {}
        for target, d in directions.items():
            angle = signed_angle(axis, d, x)
            row[f"{target}_axial"] = resultant(angle, 2)
            row[f"{target}_directional"] = resultant(angle, 1)
        out["axes"][name] = row
    out["thumb_on_plus_y_pct"] = float(100 * ((directions["thumb"] * y).sum(-1) > 0).double().mean())
    rest = hand.rest_vertices[palm_ids].double()
    palm_normal = axis_angle_to_matrix(batch.grasp[:, 3:6].double()) @ torch.linalg.svd(rest - rest.mean(0)).Vh[-1]
    towards = torch.sign(((points.mean(1) - palm) * palm_normal).sum(-1, keepdim=True))
    offset = palm - at
    out["palm_normal_cos_minus_x_median"] = float(-((towards * palm_normal) * x).sum(-1).median())
    out["palm_from_origin_cm_median"] = float(100 * offset.norm(dim=-1).median())
    out["palm_offset_cos_x_median"] = float(((offset * x).sum(-1) / offset.norm(dim=-1).clamp_min(1e-12)).median())
    return out


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", type=Path, default=Path("results"), help="the run's results folder")
    ap.add_argument("--tasks", nargs="+", default=["placing"])
    ap.add_argument("--splits", nargs="+", default=["train", "test"])
    ap.add_argument("--power", type=float, default=2.0, help="the frame's contact power (network.contact_power)")
    ap.add_argument("--origin", default="centroid", help="the frame's origin (network.origin)")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks/results/frame_axes.json")
    a = ap.parse_args(argv)
    hand = HandModel(HandAssets.load(a.results / "hand/hand.npz"))
    out: dict = {"commit": commit_label(), "cpu": cpu_name(), "power": a.power, "origin": a.origin, "tasks": {}}
    for task in a.tasks:
        out["tasks"][task] = {}
        for split in a.splits:
            paths = sorted((a.results / f"maps/{task}/{split}").glob("shard-*.zarr"))
            if not paths:
                raise SystemExit(f"{a.results}/maps/{task}/{split}: no map shards (run the maps stage first)")
            data = MapDataset(paths, per="grasp")
            res = frame_axes(hand, Batch.collate([data[i] for i in range(len(data))]), a.power, a.origin)
            out["tasks"][task][split] = res
            print(f"{task} {split} ({res['grasps']} grasps; spread evenly: {res['uniform_axial_resultant']:.3f}):")
            for name, row in res["axes"].items():
                print(f"  {name:16s} " + "  ".join(f"{k} {v:.3f}" for k, v in row.items()))
            print(f"  thumb on +y {res['thumb_on_plus_y_pct']:.1f} %; palm normal . -x {res['palm_normal_cos_minus_x_median']:.2f};"
                  f" palm {res['palm_from_origin_cm_median']:.1f} cm from the origin, cos with x"
                  f" {res['palm_offset_cos_x_median']:.2f}")
    write_json(a.out, out)
    return out


if __name__ == "__main__":
    main()
