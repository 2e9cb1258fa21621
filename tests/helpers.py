"""Helpers and small settings shared by several test modules (``from helpers import ...``): their one home, so
that no test module imports another. Shared fixtures are in tests/conftest.py."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import torch

from tohgs.assets.objects import prepare_object
from tohgs.assets.sources import ObjectSpec
from tohgs.config import validate_config
from tohgs.data.batch import Batch
from tohgs.data.maps import MapDataset
from tohgs.data.scenes import SceneSet
from tohgs.models.component import build_component
from tohgs.models.pose_prior import PosePrior, PosePriorConfig

# --- benchmarks ------------------------------------------------------------------------------------------


def load_benchmark(name: str) -> ModuleType:
    """The script ``benchmarks/<name>.py`` as a module (the benchmarks folder is not a package)."""
    path = Path(__file__).resolve().parent.parent / "benchmarks" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# --- objects ---------------------------------------------------------------------------------------------

#: The default config's objects block.
OBJECTS_CFG = validate_config({})["objects"]
#: CoACD settings that decompose a small object in about a second (coarser than the default's).
FAST_DECOMPOSITION = {**OBJECTS_CFG["decomposition"], "threshold": 0.2, "max_convex_hull": 6,
                      "preprocess_resolution": 20, "resolution": 500, "mcts_iterations": 20, "mcts_nodes": 5}


def prepare_small_object(spec: ObjectSpec, out: str | Path, cache: str | Path | None) -> dict[str, Any]:
    """:func:`~tohgs.assets.objects.prepare_object` with the default sizes and density, scale 1, seed 0 and
    :data:`FAST_DECOMPOSITION`; returns its ``meta``."""
    return prepare_object(spec, out, OBJECTS_CFG["size"], 1.0, FAST_DECOMPOSITION, OBJECTS_CFG["density"], 0, cache)


# --- scenes ----------------------------------------------------------------------------------------------

def placing_scene(obstacle_xy: tuple[float, float] | None) -> SceneSet:
    """One Placing configuration: the cube brick at (0, 0) picked and put at (0.3, 0); optionally one
    obstacle (a cube brick) near the initial pose."""
    up = [0.0, 0.0, 0.0, 1.0]
    init = np.array([[0.0, 0.0, 0.03, *up]])
    goal = np.array([[0.3, 0.0, 0.03, *up]])
    n_obs = 0 if obstacle_xy is None else 1
    obs = np.array([[*obstacle_xy, 0.03, *up]]) if n_obs else np.zeros((0, 7))
    return SceneSet(task="placing", object="brick-cube", target_init_pose=init, target_goal_pose=goal,
                    support_id=np.zeros(1, np.int32), support_pose=np.array([[0.0, 0.0, 0.0, *up]]),
                    base_id=np.full(1, -1, np.int32), base_pose=np.full((1, 7), np.nan),
                    obstacle_offsets=np.array([0, n_obs], np.int64), obstacle_id=np.zeros(n_obs, np.int32),
                    obstacle_pose=obs, objects=["brick-cube"], supports=["table"])


# --- hands -----------------------------------------------------------------------------------------------

def pose_prior(hand) -> PosePrior:
    """An untrained FLEX pose prior centred on the hand's prior mean (std 0.1)."""
    prior = PosePrior(PosePriorConfig()).eval()
    prior.mean.copy_(torch.as_tensor(hand.assets.prior_mean, dtype=torch.float32))
    prior.std.fill_(0.1)
    return prior


# --- networks --------------------------------------------------------------------------------------------

#: A PointNet++ small enough for tests.
SMALL_PN = {"sa": [[32, 0.05, 8, [16, 32]], [8, 0.1, 8, [32, 32]], [0, 0.0, 0, [32, 48]]], "fp": [[32], [32], [32]]}
#: Ours as a method block.
OURS = {"label": "Ours", "kind": "contact_grasp", "contact": "contact_diffuser", "grasp": "grasp_diffuser"}
#: Tiny networks of Ours' two components.
TINY = {"contact_diffuser": {"d_model": 16, "n_blocks": 1, "pointnet": SMALL_PN},
        "grasp_diffuser": {"d_model": 16, "n_blocks": 1, "pointnet": SMALL_PN}}
#: Training settings of a few seconds.
SETTINGS = {"steps": 10, "batch": 3, "warmup": 2, "log_every": 2, "checkpoint_every": 5, "train_points": 128,
            "device": "cpu"}


def prepared_component(kind: str, network: dict[str, Any], shard_path: str | Path, hand) -> tuple[Any, MapDataset]:
    """A component built from ``network`` (seed 0) and prepared on one map shard; and that shard's dataset (per
    grasp, rotated about z)."""
    torch.manual_seed(0)
    model = build_component(kind, network)
    data = MapDataset([shard_path], per="grasp", rotation="z", seed=0)
    model.prepare(data, "placing", hand)
    return model, data


def train_steps(model, data: MapDataset, steps: int, batch: int = 8, lr: float = 2e-3):
    """``model`` trained by Adam for ``steps`` steps on random batches of ``data`` (seed 0); in eval mode."""
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    gen = torch.Generator().manual_seed(0)
    rng = np.random.default_rng(0)
    for step in range(steps):
        items = [data.item(int(i), step) for i in rng.integers(0, len(data), batch)]
        loss = model.loss(Batch.collate(items), gen)["loss"]
        opt.zero_grad()
        loss.backward()
        opt.step()
    return model.eval()
