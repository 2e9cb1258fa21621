"""Inside and outside of a scene given only as a point cloud with normals (what a method sees of the
scene: :class:`tohgs.data.batch.Batch` ``scene`` / ``scene_normals``), in torch.

The signed distance of a query point is its offset from the nearest cloud point along that point's outward
normal (point-to-plane): negative inside the surface the cloud samples. It is exact on flat faces and a
fair proxy elsewhere while the cloud is dense compared with the query's depth (the default scene cloud
has a point every 1-2 cm); far from the cloud (beyond ``max_depth``) a point counts as outside, so that
a hand behind an open edge of a cropped scene is not called inside. The evaluation's OPP uses the scene
meshes instead (:mod:`tohgs.metrics.evaluate`); this is what a method can know.
"""

from __future__ import annotations

import torch


def cloud_signed_distance(query: torch.Tensor, cloud: torch.Tensor, normals: torch.Tensor) -> torch.Tensor:
    """(B, Q) point-to-plane signed distance (m) of (B, Q, 3) query points to (B, M, 3) cloud points with
    (B, M, 3) unit outward normals, measured at each query's nearest cloud point (found without
    gradient; differentiable in the query)."""
    with torch.no_grad():
        idx = torch.cdist(query, cloud).argmin(-1)
    near = torch.gather(cloud, 1, idx[..., None].expand(-1, -1, 3))
    near_n = torch.gather(normals, 1, idx[..., None].expand(-1, -1, 3))
    return ((query - near) * near_n).sum(-1)


def inside_cloud(query: torch.Tensor, cloud: torch.Tensor, normals: torch.Tensor, max_depth: float = 0.05
                 ) -> torch.Tensor:
    """(B, Q) bool: query points behind the cloud's surface, by at most ``max_depth`` (m)."""
    d = cloud_signed_distance(query, cloud, normals)
    return (d < 0) & (d > -max_depth)


def penetration_fraction(query: torch.Tensor, cloud: torch.Tensor, normals: torch.Tensor, max_depth: float = 0.05
                         ) -> torch.Tensor:
    """(B,) the fraction of each hand's (B, V, 3) vertices inside the cloud's surface (OPP from a cloud)."""
    return inside_cloud(query, cloud, normals, max_depth).float().mean(-1)
