"""Kind ``filtered``: another method's grasps, with those that enter the scene dropped. F-GraspTTA (paper
section 5.1) is GraspTTA filtered with the init-to-goal transform that ICP estimates from the scene clouds.

Key of the method block: ``of``, the method whose predictions are filtered (its prediction store is an
input of the job; the grasps, maps and goal poses are its own, so F-GraspTTA's kept grasps are exactly
GraspTTA's). The prediction setting ``filter`` (:class:`FilterSettings`) is this kind's.

Per test configuration: the target's init-to-goal transform is estimated (``transform: icp``, the paper's:
:func:`estimate_goal_transform`; or ``true``, the true transform, the filter's bound); each hand is carried
with that estimate; the hands with more than ``max_opp`` of their vertices inside the scene cloud
(:mod:`tohgs.geometry.cloud`, from the cloud and its normals, not the evaluation's meshes) at the initial
or the estimated goal pose are discarded (the prediction's ``kept`` flags). The stored goal grasps stay the
base method's, carried with the true transform: a hand that holds the object goes where the object goes,
and the estimate only decides what is kept. The ICP error against the true transform and the share kept
are recorded per configuration (the store's ``diagnostics``). The goal transforms of ``chunk``
configurations are estimated together (:func:`estimate_goal_transforms`; the same estimates as one at a
time).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch

from tohgs.geometry.cloud import penetration_fraction
from tohgs.geometry.registration import ICPSettings, register_many, transform_error
from tohgs.methods.base import Method, Prediction, Request, SamplingSettings
from tohgs.settings import block, settings_from

TRANSFORMS = ("icp", "true")


@dataclass(frozen=True)
class FilterSettings:
    """The filter: ``transform`` ``icp`` (the estimate of :func:`estimate_goal_transform`) or ``true``;
    ``max_opp``, the largest share of a hand's vertices inside the scene at either pose (the paper's
    0.05); ``max_depth`` (m), how far behind the scene cloud's surface a vertex still counts as inside;
    ``moved_distance`` (m), how far a goal-scene point must be from the initial scene to count as moved;
    ``icp``, a mapping of :class:`tohgs.geometry.registration.ICPSettings`."""

    transform: str = "icp"
    max_opp: float = 0.05
    max_depth: float = 0.05
    moved_distance: float = 0.005
    icp: dict | None = None

    def __post_init__(self):
        if self.transform not in TRANSFORMS:
            raise ValueError(f"filter.transform must be one of {TRANSFORMS}, not {self.transform!r}")


def scene_views(points: np.ndarray, goal_transform: np.ndarray, scene: np.ndarray, seed: int
                ) -> tuple[np.ndarray, np.ndarray]:
    """The initial and the goal scene clouds, (Ns + N / 2, 3) each: the scene cloud with the target at its
    pose. The target's (N, 3) points are split into two disjoint random halves, one per scene, so that the
    two clouds sample the object independently, as two scans would (the same points carried by the true
    transform would make registration exact by construction)."""
    n = len(points)
    order = np.random.default_rng(seed).permutation(n)
    a, b = order[: n // 2], order[n // 2:]
    at_goal = points[b] @ goal_transform[:3, :3].T + goal_transform[:3, 3]
    return np.concatenate([scene, points[a]]), np.concatenate([scene, at_goal])


def estimate_goal_transform(object_points: np.ndarray, init_scene: np.ndarray, goal_scene: np.ndarray,
                            icp: ICPSettings, moved_distance: float) -> tuple[np.ndarray, int]:
    """The target's init-to-goal transform (4, 4) from the two scene clouds, and how many goal-scene points
    moved.

    The scene around the target does not move, so ICP between the two whole clouds finds the identity;
    the points of the goal scene farther than ``moved_distance`` from every initial-scene point are what
    moved (the target at its goal pose), and the object's (N, 3) cloud at the initial pose is registered
    onto them (:func:`tohgs.geometry.registration.register`)."""
    return estimate_goal_transforms([(object_points, init_scene, goal_scene)], icp, moved_distance)[0]


def estimate_goal_transforms(views: list[tuple[np.ndarray, np.ndarray, np.ndarray]], icp: ICPSettings,
                             moved_distance: float) -> list[tuple[np.ndarray, int]]:
    """:func:`estimate_goal_transform` of several configurations' (object points, initial scene, goal
    scene), their registrations by :func:`tohgs.geometry.registration.register_many`."""
    from scipy.spatial import cKDTree

    out: list[tuple[np.ndarray, int]] = []
    pairs, where = [], []
    for object_points, init_scene, goal_scene in views:
        d, _ = cKDTree(init_scene).query(goal_scene)
        moved = goal_scene[d > moved_distance]
        out.append((np.eye(4), len(moved)))  # the target barely moved (< 3 points): nothing to register
        if len(moved) >= 3:
            where.append(len(out) - 1)
            pairs.append((object_points, moved))
    for i, reg in zip(where, register_many(pairs, icp)):
        out[i] = (reg.transform, out[i][1])
    return out


@dataclass(frozen=True)
class FilteredSettings(SamplingSettings):
    """Every job's settings and ``filter``, the filter's (:class:`FilterSettings`)."""

    filter: FilterSettings = block(FilterSettings)


class Filtered(Method):
    """The base method's grasps, those entering the scene at either pose discarded (module docstring)."""

    Settings = FilteredSettings

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        if self.hand is None or self.base is None:
            raise ValueError(f"method {self.name!r}: a filter needs the hand model and the base method's predictions")
        self.filter = self.settings.filter
        self.icp = settings_from(ICPSettings, self.filter.icp)
        arrays, attrs = self.base
        self.rows = {(attrs["objects"][int(o)], int(c)): i
                     for i, (o, c) in enumerate(zip(arrays["object_id"], arrays["config_index"]))}

    def predict(self, batch, shard, row, generator, rng) -> Prediction | None:
        return self.predict_many([Request(batch, shard, row, generator, rng)])[0]

    def predict_many(self, requests: list[Request]) -> list[Prediction | None]:
        """Per configuration the base method's grasps and its seed (from its own stream, in order); the
        goal transforms of all of them estimated as one batch (:func:`estimate_goal_transforms`), whose
        time is shared equally; then each configuration's filter."""
        arrays, _ = self.base
        staged = []  # (index, base row, network-frame grasps, seed)
        for j, r in enumerate(requests):
            key = (r.shard.attrs["objects"][int(r.shard.object_id[r.row])], int(r.shard.config_index[r.row]))
            if key not in self.rows:  # the base method predicted nothing here
                continue
            i = self.rows[key]
            grasp = np.asarray(arrays["grasp_init"][i], dtype=np.float64).copy()
            grasp[:, :3] -= r.shard.centroid[r.row]  # back to the network frame
            staged.append((j, i, grasp, int(r.rng.integers(2**31))))
        t0 = time.perf_counter()
        estimates = self.goal_transforms([requests[j].batch for j, *_ in staged], [seed for *_, seed in staged])
        share = (time.perf_counter() - t0) / max(1, len(staged))
        out: list[Prediction | None] = [None] * len(requests)
        for (j, i, grasp, _), (estimate, info) in zip(staged, estimates):
            t1 = time.perf_counter()
            batch = requests[j].batch
            kept, info = self.keep(batch, torch.as_tensor(grasp, dtype=torch.float32, device=batch.device), estimate,
                                   info)
            out[j] = Prediction(np.asarray(arrays["contact"][i], np.float32), grasp,
                                {"filter": share + time.perf_counter() - t1},
                                kept=kept & np.asarray(arrays["kept"][i], bool), info=info)
        return out

    def goal_transforms(self, batches: list, seeds: list[int]) -> list[tuple[np.ndarray, dict[str, float]]]:
        """Per configuration (its batch and seed): the (4, 4) init-to-goal transform the filter uses (the
        ICP estimate, or the true one) and its record (the estimate's error against the truth, the moved
        points)."""
        truths = [b.goal_transform[0].cpu().numpy().astype(np.float64) for b in batches]
        if self.filter.transform != "icp":
            return [(t, {}) for t in truths]
        views = []
        for b, truth, seed in zip(batches, truths, seeds):
            points = b.points[0].cpu().numpy().astype(np.float64)
            views.append((points, *scene_views(points, truth, b.scene[0].cpu().numpy().astype(np.float64), seed)))
        out = []
        for (points, _, _), truth, (estimate, moved) in zip(views, truths, estimate_goal_transforms(
                views, self.icp, self.filter.moved_distance)):
            info = {f"icp_{k}": v for k, v in transform_error(estimate, truth, points).items()}
            out.append((estimate, {**info, "icp_moved_points": float(moved)}))
        return out

    def keep(self, batch, grasp: torch.Tensor, estimate: np.ndarray, info: dict[str, float]
             ) -> tuple[np.ndarray, dict[str, float]]:
        """(S,) which of the (S, 51) network-frame hands pass with the (4, 4) goal transform ``estimate``,
        and the configuration's record (``info``, then the OPPs from the scene cloud, how many were kept)."""
        f = self.filter
        info = dict(info)
        with torch.no_grad():
            v_init = self.hand(grasp).vertices
            T = torch.as_tensor(estimate, dtype=v_init.dtype, device=v_init.device)
            v_goal = v_init @ T[:3, :3].T + T[:3, 3]
            n = len(grasp)
            cloud, normals = batch.scene[:1].expand(n, -1, -1), batch.scene_normals[:1].expand(n, -1, -1)
            opp_init = penetration_fraction(v_init, cloud, normals, f.max_depth)
            opp_goal = penetration_fraction(v_goal, cloud, normals, f.max_depth)
        kept = ((opp_init <= f.max_opp) & (opp_goal <= f.max_opp)).cpu().numpy()
        info.update({"cloud_init_opp": float(opp_init.mean()), "cloud_goal_opp": float(opp_goal.mean()),
                     "kept": float(kept.sum())})
        return kept, info


METHOD = Filtered
