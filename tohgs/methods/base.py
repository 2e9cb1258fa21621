"""The interface of a method kind, the settings every prediction job reads, and a method's contact source."""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
import torch

from tohgs.data.batch import Batch
from tohgs.data.maps import MapShard
from tohgs.geometry.contact_parts import thumb_signed_by
from tohgs.geometry.neighbours import nearest_neighbours
from tohgs.methods import GROUND_TRUTH, NO_CONTACT
from tohgs.settings import build_blocks


@dataclass(frozen=True)
class SamplingSettings:
    """The settings every prediction job reads (:func:`tohgs.methods.predict.predict`): ``samples`` S per
    configuration (the paper's 16), the ``seed``, torch ``threads``, the ``device`` and ``chunk``, the test
    configurations asked of the method at once (:meth:`Method.predict_many`; the same grasps either way).

    A method kind's ``Settings`` (:attr:`Method.Settings`) is this class or a subclass with the keys the kind
    reads besides, among them the settings blocks it owns (:func:`tohgs.settings.block`); the schema's
    ``$defs.method_kinds.<kind>.settings`` lists the same keys (a test keeps the two equal), and a job is
    given exactly those: the config's ``prediction`` block overlaid with the method's ``settings``."""

    samples: int = 16
    seed: int = 0
    threads: int = 1
    device: str = "auto"
    chunk: int = 8  # configurations per batch of an optimising method (1: one at a time; bounds memory)

    def __post_init__(self):
        if self.chunk < 1:
            raise ValueError(f"prediction.chunk must be at least 1, got {self.chunk}")
        build_blocks(self)


@dataclass(frozen=True)
class GeneratorSettings(SamplingSettings):
    """The settings of a kind that samples a trained generator, besides every job's: ``sampler`` ``ddpm``
    (all T steps) or ``ddim`` with ``steps`` steps; GraspDiffuser's classifier-free ``guidance`` scale (1:
    none; needs cond_dropout); ``contact_smoothing``, the neighbours over which a contact component's maps are
    averaged (0 or 1: none)."""

    sampler: str = "ddim"
    steps: int = 20
    guidance: float = 1.0
    contact_smoothing: int = 0


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

    Subclasses set ``Settings`` (the settings the kind reads: :class:`SamplingSettings` or a subclass) and
    implement :meth:`predict`; an optimising method also overrides :meth:`predict_many` to solve the hands
    of several configurations as one batch, with the same grasps per configuration as :meth:`predict`.
    """

    Settings: ClassVar[type[SamplingSettings]] = SamplingSettings

    def __init__(self, name: str, cfg: dict[str, Any], models: dict[str, torch.nn.Module], settings: SamplingSettings,
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


def smooth_contact(points: torch.Tensor, contact: torch.Tensor, k: int) -> torch.Tensor:
    """Each contact value replaced by the mean over its ``k`` nearest points (itself among them).

    Args:
        points: (N, 3) object points, m.
        contact: (S, N) contact maps of those points, in [0, 1].
        k: neighbours; ``k <= 1`` returns ``contact`` unchanged.

    Returns:
        (S, N) smoothed maps, in [0, 1].
    """
    if k <= 1:
        return contact
    k = min(k, points.shape[0])
    own = torch.arange(points.shape[0], device=points.device)[:, None]
    nn = torch.cat([own, nearest_neighbours(points[None], k - 1)[0]], -1)  # (N, k): itself, then its k - 1 nearest
    return contact[:, nn].mean(-1)


class ContactSource:
    """Where a method's contact maps come from, the method key ``key`` (``contact``): a contact component
    (its ``sample_contact``, smoothed by ``settings.contact_smoothing``), :data:`tohgs.methods.GROUND_TRUTH`
    (the configuration's own task-grasp maps, :meth:`Method.ground_truth`: never smoothed) or
    :data:`tohgs.methods.NO_CONTACT` (the generator reads no map)."""

    def __init__(self, method: Method, key: str = "contact"):
        self.method, self.name = method, method.cfg[key]
        self.model = None if self.name in (GROUND_TRUTH, NO_CONTACT) else method.model(key)

    @property
    def reads_maps(self) -> bool:
        """Whether there are maps (the source is not ``none``)."""
        return self.name != NO_CONTACT

    def maps(self, batch: Batch, shard: MapShard, row: int, generator: torch.Generator, signed_by=None, **extra: Any
             ) -> torch.Tensor | None:
        """(B, N) contact maps in [0, 1] for ``batch`` (B copies of configuration ``row`` of ``shard``): the
        component's, sampled with the method's sampler from ``generator`` (``extra``: its guidance arguments);
        the configuration's ground truth cycled to B (an empty (0, N) tensor where it has no task grasp); None
        for ``none``. ``signed_by`` (a hand model; ground truth only): each map signed by its grasp's thumb,
        in [-1, 1] (:func:`tohgs.geometry.contact_parts.thumb_signed`), for a grasp model that reads them."""
        if not self.reads_maps:
            return None
        s = self.method.settings
        if self.model is not None:
            if signed_by is not None:
                raise ValueError(f"contact {self.name!r} samples maps without the thumb's sign; only the ground "
                                 "truth's grasps sign them")
            contact = self.model.sample_contact(batch, s.sampler, s.steps, generator, **extra)
            return smooth_contact(batch.points[0], contact, s.contact_smoothing)
        ids = self.method.ground_truth(shard, row, batch.size)
        contact = torch.as_tensor(shard.contact[ids], device=batch.device)
        if signed_by is not None and len(ids):
            grasp = torch.as_tensor(shard.grasp[ids], dtype=batch.points.dtype, device=batch.device)
            contact = thumb_signed_by(signed_by, grasp, batch.points, contact)
        return contact


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
