"""The interface of a method kind, and the sampling settings every method shares."""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from tohgs.data.batch import Batch
from tohgs.data.maps import MapShard


@dataclass(frozen=True)
class PredictSettings:
    """``samples`` S per configuration (the paper's 16); sampler ``ddpm`` (all T steps) or ``ddim`` with
    ``steps`` steps; ``seed``; ``device``; GraspDiffuser's classifier-free ``guidance`` scale;
    ``contact_smoothing``, the neighbours over which ContactDiffuser's maps are averaged (0: none); ``tta``,
    ``filter``, ``contactgen`` and ``flex``: GraspTTA's adaptation, F-GraspTTA's filter, ContactGen's solver
    and FLEX's optimisation (:mod:`tohgs.methods.grasp_tta`, :mod:`tohgs.methods.filtered`,
    :mod:`tohgs.methods.contact_gen`, :mod:`tohgs.methods.flex`); ``steer``, scene-aware guidance of
    GraspDiffuser's sampling (:mod:`tohgs.models.guidance`; beyond the paper, off by default); ``chunk``,
    the test configurations an optimising method solves as one batch of (configurations x samples) hands
    (:meth:`Method.predict_many`; 1: one at a time, the same grasps either way). A method's ``settings``
    block overlays the config's ``prediction`` block (the two sub-blocks key by key)."""

    samples: int = 16
    sampler: str = "ddim"
    steps: int = 20
    seed: int = 0
    threads: int = 1
    device: str = "auto"
    guidance: float = 1.0  # GraspDiffuser's classifier-free guidance scale (1: none; needs cond_dropout)
    contact_smoothing: int = 0  # k of smooth_contact for a contact component's maps (0 or 1: none)
    tta: dict = field(default_factory=dict)  # tohgs.grasps.tta.TTASettings
    filter: dict = field(default_factory=dict)  # tohgs.methods.filtered.FilterSettings
    contactgen: dict = field(default_factory=dict)  # tohgs.grasps.contactgen_solver.SolverSettings
    flex: dict = field(default_factory=dict)  # tohgs.grasps.flex.FlexSettings
    steer: dict = field(default_factory=dict)  # tohgs.models.guidance.GuidanceSettings (scene-aware guidance)
    chunk: int = 8  # configurations per batch of an optimising method (1: one at a time; bounds memory)

    def __post_init__(self):
        if self.chunk < 1:
            raise ValueError(f"prediction.chunk must be at least 1, got {self.chunk}")


@dataclass
class Prediction:
    """One configuration's S predictions: ``contact`` (S, N) the maps the grasps were made from, in [0, 1];
    ``grasp`` (S, 51) grasps at the initial pose in the network frame; ``seconds`` per stage; ``kept``
    (S,) False for a grasp the method discarded (None: all kept); ``info``, numbers the method records
    of the configuration (the store's ``diagnostics``)."""

    contact: np.ndarray
    grasp: np.ndarray
    seconds: dict[str, float] = field(default_factory=dict)
    kept: np.ndarray | None = None
    info: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class Request:
    """One test configuration to predict: ``batch`` the configuration repeated S times (no contact, no
    grasp), ``shard`` / ``row`` where it lies, ``generator`` (torch) and ``rng`` (numpy) its seeded streams
    (:func:`tohgs.methods.predict.configuration_streams`)."""

    batch: Batch
    shard: MapShard
    row: int
    generator: torch.Generator
    rng: np.random.Generator


class Method:
    """A method kind: built once per prediction job from its config block, its trained components (by
    config name, eval mode, on ``device``), the settings, the hand model (on ``device``; the methods that
    pose hands use it) and, for a method of another method (``filtered``), that method's prediction store
    (arrays, attrs); then asked for each test configuration.

    Subclasses set ``needs`` (the method keys that must name components) and implement :meth:`predict`;
    an optimising method also overrides :meth:`predict_many` to solve the hands of several configurations
    as one batch, with the same grasps per configuration as :meth:`predict`.
    """

    def __init__(self, name: str, cfg: dict[str, Any], models: dict[str, torch.nn.Module], settings: PredictSettings,
                 device: torch.device, hand: torch.nn.Module | None = None,
                 base: tuple[dict[str, np.ndarray], dict[str, Any]] | None = None):
        self.name, self.cfg, self.models, self.settings, self.device = name, cfg, models, settings, device
        self.hand, self.base = hand, base

    def require_hand(self, why: str) -> torch.nn.Module:
        """The hand model, or a clear error naming the method and ``why`` it poses hands."""
        if self.hand is None:
            raise ValueError(f"method {self.name!r}: {why}; the prediction job needs the hand model")
        return self.hand

    def ground_truth(self, shard: MapShard, row: int, count: int | None = None) -> np.ndarray:
        """The ground-truth task grasps this method reads for configuration ``row`` (``count``, default S):
        :func:`ground_truth_pick` with the job's seed, so every ground-truth row of a seed reads the same."""
        return ground_truth_pick(shard, row, self.settings.samples if count is None else count, self.settings.seed)

    def model(self, key: str) -> torch.nn.Module:
        """The component the method key ``key`` names (a clear error when the job was not given it)."""
        comp = self.cfg.get(key)
        if comp not in self.models:
            raise ValueError(f"method {self.name!r}: its {key} {comp!r} is not among the trained components "
                             f"given ({sorted(self.models)})")
        return self.models[comp]

    def predict(self, batch: Batch, shard: MapShard, row: int, generator: torch.Generator,
                rng: np.random.Generator) -> Prediction | None:
        """The S predictions of one test configuration: ``batch`` is the configuration repeated S times
        (no contact, no grasp), ``shard`` / ``row`` where it lies (a ground-truth source reads them);
        ``generator`` (torch) and ``rng`` (numpy) are the configuration's seeded streams
        (:func:`tohgs.methods.predict.configuration_streams`). None: the configuration
        cannot be predicted (e.g. ground-truth maps where it has no task grasp)."""
        raise NotImplementedError

    def predict_many(self, requests: list[Request]) -> list[Prediction | None]:
        """The predictions of several configurations (``settings.chunk`` of them at most), in order: each
        as :meth:`predict` would make it alone (its own streams, maps, selections). This default predicts
        them one at a time."""
        return [self.predict(r.batch, r.shard, r.row, r.generator, r.rng) for r in requests]


def gt_rows(shard: MapShard, row: int) -> np.ndarray:
    """The task grasps (rows of the shard's grasp arrays) of configuration ``row``."""
    return np.flatnonzero(shard.grasp_config == row)


def ground_truth_pick(shard: MapShard, row: int, count: int, seed: int) -> np.ndarray:
    """(count,) the task grasps (rows of the shard's grasp arrays) that every ground-truth row reads for
    configuration ``row``: its task grasps in a random order drawn from ``seed``, the object's name and the
    configuration's index, cycled to ``count`` (a configuration with fewer grasps repeats them in turn);
    empty for a configuration without task grasps. The ``Dataset`` row and the ground-truth-contact rows of a
    seed thus evaluate the same grasps of the same configurations (paired rows)."""
    ids = gt_rows(shard, row)
    if len(ids) == 0:
        return ids
    name = shard.attrs["objects"][int(shard.object_id[row])]
    rng = np.random.default_rng([int(seed), zlib.crc32(name.encode()), int(shard.config_index[row]), GROUND_TRUTH_STREAM])
    return rng.permutation(ids)[np.arange(count) % len(ids)]


GROUND_TRUTH_STREAM = 0x67  # the key of the ground-truth pick's stream, apart from a configuration's sampling streams
