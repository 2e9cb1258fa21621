# Configuration validation, the object selection, wildcard constraints and helper functions.
import os
import sys
from collections import Counter
from pathlib import Path
from types import SimpleNamespace

REPO = Path(workflow.basedir).parent
if str(REPO) not in sys.path:  # parse time only; jobs import the installed package (pip install -e .)
    sys.path.insert(0, str(REPO))

from tohgs.config import ConfigError, validate_config
from tohgs.assets.objects import check_split_sizes, read_catalog
from tohgs.assets.sources import select_objects, task_set

try:
    validate_config(config)
except ConfigError as err:
    raise WorkflowError(f"invalid configuration: {err}") from None

# The task sets the configured tasks draw their targets from (bricks for stacking, objects otherwise).
TASK_SETS = sorted({task_set(t) for t in config["scenes"]["tasks"]})

SKIPPED_FILES = []  # (file, reason) of user-folder files that cannot be used
try:
    OBJECTS = {spec.name: spec for spec in select_objects(config["objects"], config["seed"], skipped=SKIPPED_FILES)}
    check_split_sizes(Counter(spec.task_set for spec in OBJECTS.values()), config["objects"]["split"], TASK_SETS)
except (ValueError, FileNotFoundError) as err:
    raise WorkflowError(f"invalid configuration: {err}") from None
for _file, _reason in SKIPPED_FILES:
    print(f"objects.sources.dir: skipped {_file}: {_reason}", file=sys.stderr)

OBJECT_NAME = "(pb|brick|dir)-[a-z0-9-]+"  # the {object} wildcard (see tohgs.assets.sources)


def code(*modules):
    """The tohgs source files a job runs: packages ("sim": all its modules) or single modules
    ("data/scenes", "config"). They are the job's code inputs, so an edit makes it stale."""
    files = []
    for name in modules:
        path = REPO / "tohgs" / name
        single = path.with_suffix(".py")
        files += [single] if single.is_file() else sorted(path.glob("*.py"))
    return [os.path.relpath(f) for f in files]


def _canonical(value):
    """Mappings with sorted keys, recursively: params compare by repr, so key order must not matter."""
    if isinstance(value, dict):
        return {k: _canonical(value[k]) for k in sorted(value)}
    if isinstance(value, list):
        return [_canonical(v) for v in value]
    return value


def setting(*keys):
    """The config value at ``keys`` (e.g. ``setting("objects", "density")``) for a rule's params."""
    value = config
    for k in keys:
        value = value[k]
    return _canonical(value)


def object_dirs():
    """Every selected object's folder (accepted or rejected: the catalog records which)."""
    return expand("results/objects/{object}", object=sorted(OBJECTS))


def _portable(path):
    """``path`` relative to the working directory when it lies inside it (the checkout's ``.venv``, a user
    folder in the checkout), else as given: a moved or re-cloned checkout then names the same inputs and
    params, and Snakemake reruns nothing."""
    rel = os.path.relpath(path)
    return path if rel.startswith("..") else rel


def object_source(wildcards):
    """The source mesh of a file-based object (none for generated bricks)."""
    spec = OBJECTS[wildcards.object]
    return [_portable(spec.path)] if spec.path else []


def object_spec(wildcards):
    spec = OBJECTS[wildcards.object].to_dict()
    if spec["path"]:
        spec["path"] = _portable(spec["path"])
    return _canonical(spec)


def object_size(wildcards):
    """Size settings that apply to this object: the size range (and seed) for meshes, the scale for bricks."""
    if OBJECTS[wildcards.object].source == "bricks":
        return {"brick_scale": setting("objects", "sources", "bricks", "scale")}
    return _canonical({**config["objects"]["size"], "seed": config["seed"]})


def accepted_objects(task):
    """Accepted objects of a task's set (bricks for stacking), read from the catalog checkpoint."""
    catalog = read_catalog(checkpoints.catalog.get().output[0])
    return sorted(catalog[catalog.task_set == task_set(task)].name)


def scene_stores_of(task):
    """Every scene store of ``task``."""
    return expand("results/scenes/{task}/{object}.zarr", task=task, object=accepted_objects(task))


def scene_stores(wildcards):
    return scene_stores_of(wildcards.task)


def scene_settings(wildcards):
    """The scenes settings one task uses (so another task's settings do not make it stale)."""
    keys = ("n_configs", "max_tries", "allow_fewer", "physics", "contact_margin", wildcards.task)
    return _canonical({k: config["scenes"][k] for k in keys})


def prior_stores(wildcards):
    """The filtered prior-grasp store of every accepted object (objects and bricks)."""
    catalog = read_catalog(checkpoints.catalog.get().output[0])
    return expand("results/grasps/prior/{object}.zarr", object=sorted(catalog.name))


def plane_direction(wildcards):
    """Support planes of the synthesis for this object's source (prior_grasps.plane_direction)."""
    return config["prior_grasps"]["plane_direction"]["bricks" if OBJECTS[wildcards.object].source == "bricks" else "objects"]


SPLITS = ("train", "val", "test")


def split_objects(wildcards):
    """Accepted target objects of the task's set in the split (the catalog's split column)."""
    catalog = read_catalog(checkpoints.catalog.get().output[0])
    sel = catalog[(catalog.task_set == task_set(wildcards.task)) & (catalog.split == wildcards.split)]
    return sorted(sel.name)


def split_scene_stores(wildcards):
    return expand("results/scenes/{task}/{object}.zarr", task=wildcards.task, object=split_objects(wildcards))


def split_task_grasps(wildcards):
    return expand("results/grasps/task/{task}/{object}.zarr", task=wildcards.task, object=split_objects(wildcards))


def map_shards_of(task):
    """Every map shard of a task (all splits)."""
    return [f"results/maps/{task}/{split}/shard-{k}.zarr" for split in SPLITS
            for k in range(config["maps"]["shards"][split])]


def all_map_shards(wildcards):
    return [p for task in config["scenes"]["tasks"] for p in map_shards_of(task)]


def all_task_grasps(wildcards):
    return [f"results/grasps/task/{task}/{o}.zarr" for task in config["scenes"]["tasks"] for o in accepted_objects(task)]


MODELS = ("contact_diffuser", "grasp_diffuser")
# Prediction methods of the diffusers: where their contact maps come from.
METHOD_CONTACT = {"ours": "model", "ours-gt-contact": "ground_truth"}


def train_shards(wildcards):
    return [f"results/maps/{wildcards.task}/train/shard-{k}.zarr" for k in range(config["maps"]["shards"]["train"])]


def test_shards(wildcards):
    return [f"results/maps/{wildcards.task}/test/shard-{k}.zarr" for k in range(config["maps"]["shards"]["test"])]


def contact_model_of(wildcards):
    """ContactDiffuser's checkpoint when the method samples contact maps from it."""
    if METHOD_CONTACT[wildcards.method] == "model":
        return [f"results/models/{wildcards.task}/contact_diffuser.pt"]
    return []


def contact_source_of(wildcards):
    return METHOD_CONTACT[wildcards.method]


def prediction_outputs():
    """Every task's prediction store of every configured method."""
    return [f"results/predictions/{task}/{m}.zarr" for task in config["scenes"]["tasks"]
            for m in config["prediction"]["methods"]]


def test_scene_stores(wildcards):
    """Scene stores of the task's test objects (the configurations the predictions are of)."""
    w = SimpleNamespace(task=wildcards.task, split="test")
    return split_scene_stores(w)


def all_test_shards(wildcards):
    return [p for task in config["scenes"]["tasks"] for p in test_shards(SimpleNamespace(task=task))]


def metric_outputs(wildcards):
    """Every task's metric file of every method of the table."""
    return [f"results/metrics/{task}/{m}.parquet" for task in config["scenes"]["tasks"]
            for m in config["evaluation"]["methods"]]


def final_outputs():
    """The default target's outputs known before the catalog exists (see catalog_outputs)."""
    tasks = config["scenes"]["tasks"]
    return [
        "results/objects/catalog.csv",
        "results/objects/supports",
        "results/figures/objects.png",
        "results/figures/hand.png",
        "results/grasps/prior/summary.csv",
        "results/figures/prior_grasps.png",
        "results/maps/summary.csv",
        "results/figures/maps.png",
        "results/tables/table1.csv",
        "results/figures/contact_maps.png",
    ] + prediction_outputs() + [f"results/models/{task}/checks.json" for task in tasks] + [
        f"results/figures/{kind}_{task}.png" for task in tasks for kind in ("scenes", "predictions")]


def catalog_outputs(wildcards):
    """The default target's outputs per accepted object, known once the catalog checkpoint has run."""
    return [store for task in config["scenes"]["tasks"] for store in scene_stores_of(task)]


def hand_source(wildcards):
    """The user's MANO file when the mano backend is chosen (an input, so a new file reruns the hand)."""
    return [config["hand"]["mano_path"]] if config["hand"]["model"] == "mano" else []
