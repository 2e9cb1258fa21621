"""Canonical frames computed from a network's inputs: rotation-equivariant by construction.

The paper's protocol trains every network with random SO(3) rotations of its input and tests it upright. A
network whose input is expressed in a frame that turns with the input sees the same numbers however the
input is turned, so the rotation it was trained with cannot matter (canonicalisation; frame averaging,
Puny et al. ICLR 2022, averages over such frames where they are ambiguous). Both frames here are built from
weighted first and second moments of the object cloud, so for any rotation R (about the cloud's origin or
any point): ``frame(R x) = (R F, R o)`` for ``frame(x) = (F, o)``.

Where a moment leaves an axis undetermined (a contact region with no offset from the object's centre, an
object with two equal principal extents), the frame falls back on the next moment, and finally on a fixed
choice: such inputs get *a* frame, equivariant only up to a turn about that axis (the network then sees
one of a few views of them, each with consistent targets).

Shapes: points and normals (B, N, 3) m, weights (B, N); a frame is ``(rotation (B, 3, 3), origin (B, 3))``,
its columns the frame's axes in the input's coordinates, so that ``x' = R^T (x - o)``.
"""

from __future__ import annotations

import torch

EPS_LENGTH = 1e-4  # m: a weighted offset shorter than this leaves its axis to the fallback
EPS_RATIO = 0.05   # an offset of this share of the cloud's RMS radius counts as one


def _unit(v: torch.Tensor) -> torch.Tensor:
    return v / v.norm(dim=-1, keepdim=True).clamp_min(1e-12)


def _perp(v: torch.Tensor, axis: torch.Tensor) -> torch.Tensor:
    """(B, 3) ``v`` less its component along the unit (B, 3) ``axis``."""
    return v - (v * axis).sum(-1, keepdim=True) * axis


def _principal_perp(centred: torch.Tensor, weights: torch.Tensor, axis: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The weighted principal direction of (B, N, 3) ``centred`` points in the plane normal to the unit
    (B, 3) ``axis``, its sign chosen so that the weighted third moment along it is positive. Returns the
    (B, 3) direction and (B,) the eigenvalue gap relative to the larger one (0: undetermined in the plane)."""
    w = weights / weights.sum(-1, keepdim=True).clamp_min(1e-12)
    proj = centred - (centred * axis[:, None]).sum(-1, keepdim=True) * axis[:, None]
    cov = torch.einsum("bn,bni,bnj->bij", w, proj, proj)
    vals, vecs = torch.linalg.eigh(cov.double())  # ascending; the smallest is ~0 (along the axis)
    u = vecs[..., 2].to(centred.dtype)
    gap = ((vals[:, 2] - vals[:, 1]) / vals[:, 2].clamp_min(1e-30)).to(centred.dtype)
    skew = (w * (proj * u[:, None]).sum(-1) ** 3).sum(-1)
    u = torch.where(skew[:, None] < 0, -u, u)
    return _unit(_perp(u, axis)), gap


def _fixed_perp(axis: torch.Tensor) -> torch.Tensor:
    """A unit vector normal to each unit (B, 3) ``axis``: the coordinate axis least aligned with it, made
    normal to it (the last fallback, not equivariant)."""
    eye = torch.eye(3, dtype=axis.dtype, device=axis.device)
    pick = eye[axis.abs().argmin(-1)]
    return _unit(_perp(pick, axis))


def _frame(e1: torch.Tensor, e2: torch.Tensor) -> torch.Tensor:
    """(B, 3, 3) the right-handed frame of unit ``e1`` and unit ``e2`` normal to it (columns)."""
    return torch.stack([e1, e2, torch.cross(e1, e2, dim=-1)], -1)


def _first_axis(v: torch.Tensor, centred: torch.Tensor, radius: torch.Tensor) -> torch.Tensor:
    """``v`` made a unit vector; where it is shorter than ``EPS_RATIO`` of the (B,) ``radius``, the cloud's
    principal axis instead (sign by its third moment)."""
    ones = torch.ones(centred.shape[:2], dtype=centred.dtype, device=centred.device)
    w = ones / centred.shape[1]
    cov = torch.einsum("bn,bni,bnj->bij", w, centred, centred)
    vecs = torch.linalg.eigh(cov.double())[1][..., 2].to(centred.dtype)
    skew = (w * (centred * vecs[:, None]).sum(-1) ** 3).sum(-1)
    principal = torch.where(skew[:, None] < 0, -vecs, vecs)
    short = v.norm(dim=-1) < torch.maximum(EPS_RATIO * radius, torch.full_like(radius, EPS_LENGTH))
    return _unit(torch.where(short[:, None], principal, v))


def _second_axis(candidate: torch.Tensor | None, e1: torch.Tensor, centred: torch.Tensor, weights: torch.Tensor,
                 scale: torch.Tensor) -> torch.Tensor:
    """The second axis: ``candidate`` (or None) made normal to ``e1`` where that leaves at least
    ``EPS_RATIO`` of ``scale`` (B,); else the weighted principal direction of ``centred`` normal to ``e1``
    (sign by its third moment); where that too is undetermined (equal extents), the unweighted one; else a
    fixed direction."""
    u_w, gap_w = _principal_perp(centred, weights, e1)
    u_o, gap_o = _principal_perp(centred, torch.ones_like(weights), e1)
    axis = torch.where((gap_w > 0.05)[:, None], u_w, torch.where((gap_o > 0.05)[:, None], u_o, _fixed_perp(e1)))
    if candidate is None:
        return axis
    c = _perp(candidate, e1)
    ok = c.norm(dim=-1) >= torch.maximum(EPS_RATIO * scale, torch.full_like(scale, EPS_LENGTH))
    return torch.where(ok[:, None], _unit(c), axis)


def contact_frame_3d(points: torch.Tensor, normals: torch.Tensor, contact: torch.Tensor, power: float = 2.0,
                     origin: str = "centroid") -> tuple[torch.Tensor, torch.Tensor]:
    """The GraspDiffuser's canonical frame of an object cloud and its contact map (weights ``c ** power``).

    - origin: the contact-weighted centroid (``"centroid"``), or the object point nearest to it
      (``"surface"``: on the object, where the hand is);
    - x: from the object's centre towards the contact, the sum of the contact centroid's offset and the
      contact region's weighted mean normal times the cloud's RMS radius: both point from the object to the
      hand, and where one cancels (a pinch across the middle) the other rarely does;
    - y: the contact region's principal direction normal to x (the line from the thumb's contact to the
      fingers'), its sign by the region's third moment; falls back on the object's principal direction.

    A map without contact weighs every point alike. Returns ``(rotation (B, 3, 3), origin (B, 3))``.
    """
    w = contact.clamp_min(0) ** power
    total = w.sum(-1, keepdim=True)
    w = torch.where(total > 1e-6, w, torch.ones_like(w))
    wn = w / w.sum(-1, keepdim=True)
    centre = points.mean(1)
    centred = points - centre[:, None]
    radius = centred.norm(dim=-1).pow(2).mean(-1).sqrt().clamp_min(1e-6)
    at = (wn[..., None] * points).sum(1)
    mean_normal = (wn[..., None] * normals).sum(1)
    e1 = _first_axis(at - centre + radius[:, None] * mean_normal, centred, radius)
    e2 = _second_axis(None, e1, points - at[:, None], w, radius)
    if origin == "surface":
        nearest = (points - at[:, None]).norm(dim=-1).argmin(-1)
        at = points[torch.arange(points.shape[0], device=points.device), nearest]
    elif origin != "centroid":
        raise ValueError(f"the contact frame's origin must be 'centroid' or 'surface', not {origin!r}")
    return _frame(e1, e2), at


def scene_frame(points: torch.Tensor, d_init: torch.Tensor, d_goal: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The ContactDiffuser's canonical frame of an object cloud and its two distance maps (1 at the scene):

    - origin: the cloud's centroid;
    - x: towards the scene at the initial pose, the ``d_init``-weighted mean offset of the points from the
      centroid (the support, and obstacles, at the initial pose);
    - y: the same of ``d_goal`` normal to x (where the goal's scene lies besides x); where the goal adds no
      direction of its own (it lies along x too: the same table below), the object's principal direction
      normal to x, weighted by ``d_init + d_goal``.

    Returns ``(rotation (B, 3, 3), origin (B, 3))``.
    """
    centre = points.mean(1)
    centred = points - centre[:, None]
    radius = centred.norm(dim=-1).pow(2).mean(-1).sqrt().clamp_min(1e-6)
    v1 = (d_init[..., None] * centred).mean(1)
    v2 = (d_goal[..., None] * centred).mean(1)
    e1 = _first_axis(v1 / d_init.mean(-1, keepdim=True).clamp_min(1e-6), centred, radius)
    e2 = _second_axis(v2 / d_goal.mean(-1, keepdim=True).clamp_min(1e-6), e1, centred, d_init + d_goal + 1e-3, radius)
    return _frame(e1, e2), centre
