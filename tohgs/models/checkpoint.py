"""The one checkpoint format of every component, its loader (``torch.load(weights_only=True)``) and the device a
job loads it onto (:func:`pick_device`).

``results/models/<task>/<component>.pt`` is a dict of plain data (tensors, numbers, strings, lists, dicts),
so loading it runs no code:

================  ==================================================================================
key               value
================  ==================================================================================
format            ``"tohgs.checkpoint"``; ``format_version``: :data:`FORMAT_VERSION`
tohgs_version     the package version that wrote it
component, kind   the config's component name and its kind (:mod:`tohgs.models.component`)
task              the task it was trained for
network_config    the network config (the kind's ``Config`` as a mapping)
training_config   the training settings (:class:`tohgs.models.train.TrainSettings` as a mapping)
state_dict        the EMA weights, with the buffers the data fixed (a normaliser, the hand's wrist)
normaliser        the data normaliser (``{"mean": ..., "std": ...}``, tensors) or None
loss_curve        logged rows: ``step``, ``loss``, each term, ``lr``
seconds           training time, s; ``n_parameters``, ``n_train_grasps``
alpha_contact     the contact maps' alpha; ``hand_wrist``: the hand's rest wrist joint, m
================  ==================================================================================
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

import tohgs
from tohgs.io import atomic_path
from tohgs.models.component import Component, build_component

FORMAT = "tohgs.checkpoint"
FORMAT_VERSION = 1
REQUIRED = ("component", "kind", "task", "network_config", "training_config", "state_dict", "loss_curve")


def save_checkpoint(path: str | Path, model: Component, component: str, task: str, network_config: dict[str, Any],
                    training_config: dict[str, Any], **extra: Any) -> dict[str, Any]:
    """Write ``model``'s weights (moved to the CPU) with its metadata to ``path`` atomically; returns the dict.
    ``extra`` holds the remaining keys of the module table (``loss_curve``, ``seconds``, ...)."""
    normaliser = getattr(model, "normaliser", None)
    ckpt = {"format": FORMAT, "format_version": FORMAT_VERSION, "tohgs_version": tohgs.__version__,
            "component": component, "kind": model.kind, "task": task, "network_config": network_config,
            "training_config": training_config,
            "state_dict": {k: v.detach().cpu() for k, v in model.state_dict().items()},
            "normaliser": normaliser() if callable(normaliser) else None, **extra}
    with atomic_path(path) as tmp:
        torch.save(ckpt, tmp)
    return ckpt


def load_checkpoint(path: str | Path, map_location: str | torch.device = "cpu") -> dict[str, Any]:
    """A checkpoint or resume file as a dict, read with ``weights_only=True``: tensors, numbers, strings and
    containers only, so a file that carries code is refused and nothing in it runs.

    Raises:
        ValueError: unreadable, or not made of plain data (the message names the file).
    """
    path = Path(path)
    try:
        obj = torch.load(path, map_location=map_location, weights_only=True)
    except Exception as exc:
        raise ValueError(f"{path}: not a readable checkpoint of plain data; refused ({type(exc).__name__}: "
                         f"{str(exc).splitlines()[0] if str(exc) else ''})") from exc
    if not isinstance(obj, dict):
        raise ValueError(f"{path}: not a tohgs checkpoint (a {type(obj).__name__}, not a dict)")
    return obj


def pick_device(device: str) -> torch.device:
    """``"auto"``: CUDA when there is a device, else the CPU; ``"cpu"``; ``"cuda"`` / ``"cuda:k"``, which must exist.

    Raises:
        ValueError: a CUDA device is asked for where there is none (the message says why and what to set).
    """
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    dev = torch.device(device)
    if dev.type == "cuda":
        if not torch.cuda.is_available():
            why = ("this torch is a CPU build" if torch.version.cuda is None
                   else f"torch {torch.__version__} sees no CUDA device")
            raise ValueError(f"device {device!r} was asked for, but {why}; set the device to 'auto' (CUDA where "
                             "there is one, else the CPU) or 'cpu'")
        if dev.index is not None and dev.index >= torch.cuda.device_count():
            raise ValueError(f"device {device!r} was asked for, but there are only {torch.cuda.device_count()} "
                             "CUDA devices")
    return dev


def load_component(path: str | Path, device: str | torch.device = "cpu", task: str | None = None,
                   component: str | None = None) -> tuple[Component, dict[str, Any]]:
    """The component of a checkpoint (EMA weights, eval mode) and the checkpoint dict.

    Args:
        path: the checkpoint.
        device: where the weights go.
        task, component: what the job expects (None: not checked); a checkpoint that records another task
            or component (one copied into place) is refused.

    Raises:
        ValueError: not a tohgs checkpoint, one of another format version, one without a required key, or one
            of another task or component than the job's (the message names the file and both).
    """
    path = Path(path)
    ckpt = load_checkpoint(path)
    if ckpt.get("format") != FORMAT:
        raise ValueError(f"{path}: not a tohgs checkpoint (no format '{FORMAT}'; one of an older tohgs? retrain it)")
    if ckpt.get("format_version") != FORMAT_VERSION:
        raise ValueError(f"{path}: checkpoint format version {ckpt.get('format_version')}, this tohgs reads "
                         f"{FORMAT_VERSION}; retrain it")
    missing = [k for k in REQUIRED if k not in ckpt]
    if missing:
        raise ValueError(f"{path}: not a tohgs checkpoint (no {missing})")
    for key, want in (("task", task), ("component", component)):
        if want is not None and ckpt[key] != want:
            raise ValueError(f"{path}: a checkpoint of {key} {ckpt[key]!r}, but this job needs {key} {want!r} (a file "
                             "copied into place? retrain it: delete the file)")
    model = build_component(ckpt["kind"], ckpt["network_config"])
    model.load_state_dict(ckpt["state_dict"])
    return model.to(device).eval(), ckpt
