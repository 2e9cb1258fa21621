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



def clearance_violation(d: torch.Tensor, margin: float, max_depth: float) -> torch.Tensor:
    """(...,) ``sum |min(d - margin, 0)|`` over the last axis of signed distances ``d`` (m), leaving out
    points more than ``max_depth`` inside (behind an open edge of a cropped cloud): the obstacle term of
    FLEX and of guided sampling."""
    return ((d > -max_depth).to(d) * (margin - d).clamp(min=0)).sum(-1)


def even_subset(n: int, k: int, device: torch.device | str = "cpu") -> torch.Tensor:
    """(min(n, k),) indices spread evenly over ``range(n)`` (``k <= 0``: all ``n``): the hand vertices the
    penetration terms use."""
    k = n if k <= 0 else min(n, k)
    return torch.linspace(0, n - 1, k, device=device).round().long()

# A fixed cloud's k-d tree is built once and asked many times, mostly by hand vertices centimetres away
# from it: 32 points per leaf answers them 1.3x faster than scipy's default 16 on the default's 2048-point
# scene clouds (the same nearest point: the leaf size changes the search, not its answer).
CLOUD_LEAF_SIZE = 32


class CloudIndex:
    """Nearest-point search in one fixed cloud (an object's or a scene's) for many queries: one k-d tree
    (:data:`CLOUD_LEAF_SIZE`), built once, on the CPU; the full distance matrix on other devices. The
    optimisations that keep a hand out of a cloud ask it every few steps.

    Args:
        cloud: (M, 3) points, m.
        normals: (M, 3) their unit outward normals.
    """

    def __init__(self, cloud: torch.Tensor, normals: torch.Tensor):
        if cloud.ndim != 2 or cloud.shape[-1] != 3 or normals.shape != cloud.shape or len(cloud) == 0:
            raise ValueError(f"a cloud index needs (M >= 1, 3) points and normals, got {tuple(cloud.shape)} and "
                             f"{tuple(normals.shape)}")
        self.cloud, self.normals = cloud, normals
        self._tree = None
        if cloud.device.type == "cpu":
            from scipy.spatial import cKDTree

            self._tree = cKDTree(cloud.detach().numpy(), leafsize=CLOUD_LEAF_SIZE)

    def nearest(self, query: torch.Tensor) -> torch.Tensor:
        """(...,) the index of the nearest cloud point to each of (..., 3) query points (no gradient)."""
        with torch.no_grad():
            if self._tree is not None:
                q = query.detach().reshape(-1, 3).numpy()
                return torch.as_tensor(self._tree.query(q, k=1)[1], dtype=torch.long).reshape(query.shape[:-1])
            flat = query.detach().reshape(-1, 3)
            return torch.cat([torch.cdist(c, self.cloud).argmin(-1) for c in flat.split(65536)]).reshape(query.shape[:-1])

    def signed_distance(self, query: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
        """(...,) point-to-plane signed distance (m) of (..., 3) queries at their (...,) nearest points
        ``idx`` (:meth:`nearest`); differentiable in the query."""
        return cloud_signed_distance_at(query, self.cloud, self.normals, idx)

    def distance(self, query: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
        """(...,) Euclidean distance (m) of (..., 3) queries to their nearest points ``idx``."""
        return cloud_distance(query, self.cloud, idx)


def cloud_signed_distance_at(query: torch.Tensor, cloud: torch.Tensor, normals: torch.Tensor, idx: torch.Tensor
                             ) -> torch.Tensor:
    """(...,) point-to-plane signed distance (m) of (..., 3) queries at the (...,) points ``idx`` of an
    (M, 3) cloud with (M, 3) unit outward normals; differentiable in the query."""
    return ((query - cloud[idx]) * normals[idx]).sum(-1)


def cloud_distance(query: torch.Tensor, cloud: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
    """(...,) Euclidean distance (m) of (..., 3) queries to the (...,) points ``idx`` of an (M, 3) cloud (an
    epsilon under the root keeps the gradient finite at 0)."""
    return ((query - cloud[idx]) ** 2).sum(-1).add(1e-12).sqrt()
