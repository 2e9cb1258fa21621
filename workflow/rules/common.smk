# Configuration validation, the object selection, the components, methods and tables of the config, the
# derived code of each rule and helper functions.
import hashlib
import os
import re
import sys
from collections import Counter
from pathlib import Path
from types import SimpleNamespace

REPO = Path(workflow.basedir).parent
if (
    str(REPO) not in sys.path
):  # parse time only; jobs import the installed package (pip install -e .)
    sys.path.insert(0, str(REPO))

from tohgs.code_inputs import code_inputs
from tohgs.config_files import ConfigFileError, check_config_files
from tohgs.config import (
    ConfigError,
    add_seed_replicas,
    evaluation_sd_settings as evaluation_sd_settings_of,
    drop_ground_truth_rows,
    job_network,
    job_settings,
    load_schema,
    validate_config,
)
from tohgs.assets.splits import check_split_sizes
from tohgs.assets.sources import select_objects, task_set
from tohgs.methods import base_method, method_components, of_chain
from tohgs.models import component_checks
from tohgs.scheduler_timers import coalesce_scheduler_timers

# One pending re-scheduling timer instead of a chain per job event (tohgs/scheduler_timers.py): the
# scheduler's passes no longer pile up over a long run, and the run ends with its last job.
coalesce_scheduler_timers()

_SCHEMA = load_schema()
try:
    # Each config file read again strictly (repeated keys, aliases of aliases: tohgs/config_files.py), then
    # the merged config Snakemake built from them validated.
    check_config_files(workflow.configfiles)
    validate_config(config, _SCHEMA)
except (ConfigFileError, ConfigError) as err:
    raise WorkflowError(f"invalid configuration: {err}") from None

# The task sets the configured tasks draw their targets from (bricks for stacking, objects otherwise).
TASK_SETS = sorted({task_set(t) for t in config["scenes"]["tasks"]})

# The official dataset's import (config official.import_dir), or None: generated data.
OFFICIAL = config["official"]["import_dir"]
IMPORTED = None
# The rules that generate data (rules/objects.smk, scenes.smk, grasps.smk); with an import they are not defined.
GENERATION_RULES = (
    "prepare_object",
    "scenes",
    "prior_synthesis",
    "prior_filter",
    "prior_summary",
    "prior_figure",
    "task_grasps",
)

SKIPPED_FILES = []  # (file, reason) of user-folder files that cannot be used
MISSING_PACKAGES = []  # messages of object sources' packages that are not installed
if OFFICIAL:
    from tohgs.official.importer import read_import

    try:
        IMPORTED = read_import(OFFICIAL)
    except (ValueError, FileNotFoundError) as err:
        raise WorkflowError(
            f"invalid configuration: config key 'official.import_dir': {err}"
        ) from None
    _missing = [t for t in config["scenes"]["tasks"] if t not in IMPORTED.splits]
    if _missing:
        raise WorkflowError(
            f"invalid configuration: config key 'scenes.tasks': {', '.join(_missing)} not in the "
            f"import {OFFICIAL} (it has {', '.join(sorted(IMPORTED.splits))})"
        )
    if IMPORTED.hand != config["hand"]["model"]:
        raise WorkflowError(
            f"invalid configuration: config key 'hand.model' is {config['hand']['model']!r} but the "
            f"import {OFFICIAL} carried its grasps with the {IMPORTED.hand!r} hand: import again "
            f"with --hand {config['hand']['model']} or set hand.model: {IMPORTED.hand}"
        )
    OBJECTS = dict.fromkeys(IMPORTED.objects)  # every object the import's catalog lists
else:
    try:
        OBJECTS = {
            spec.name: spec
            for spec in select_objects(
                config["objects"],
                config["seed"],
                skipped=SKIPPED_FILES,
                missing=MISSING_PACKAGES,
            )
        }
        check_split_sizes(
            Counter(spec.task_set for spec in OBJECTS.values()),
            config["objects"]["split"],
            TASK_SETS,
        )
    except (ValueError, FileNotFoundError, ModuleNotFoundError) as err:
        raise WorkflowError(f"invalid configuration: {err}") from None
for _file, _reason in SKIPPED_FILES:
    print(f"objects.sources.dir: skipped {_file}: {_reason}", file=sys.stderr)
# A source package that is not installed: the workflow still parses (snakemake --lint needs no package but
# Snakemake's), and the first job that reads one of its meshes stops with this message (object_source).
for _message in MISSING_PACKAGES:
    print(f"{_message} (no job can read these objects' meshes)", file=sys.stderr)


def imported(path):
    """``path`` (with wildcards) inside the official import's folder (config official.import_dir)."""
    return os.path.join(OFFICIAL, path)


OBJECT_NAME = "(pb|brick|dir|ycb|off)-[a-z0-9-]+"  # the {object} wildcard (tohgs.assets.sources, tohgs.official.format)


def objects_dir_of_supports(wildcards, input):
    """The objects folder (``results/objects``), where the supports folder (an input) lies. The jobs
    that read object meshes take it as a param, so their scripts never derive paths."""
    return os.path.dirname(input.supports)


def objects_dir_of_catalog(wildcards, input):
    """The objects folder, where the catalog (an input) lies."""
    return os.path.dirname(input.catalog)


_CODE = (
    {}
)  # (script, modules) -> the code param: a workflow process reads each file once


def code(script, *modules):
    """The code a rule's jobs run, as a param: every tohgs source file its script
    (``workflow/scripts/<script>``) imports, derived from the imports, plus the modules it loads by name
    (``"models/grasp_diffuser"``: a component or method kind) and theirs (:mod:`tohgs.code_inputs`), each
    with the SHA-256 (16 hex digits) of its content. An edit of any of them changes the param and makes the
    jobs stale; a touch does not. A param, not input files: the scheduler stats every input of every ready
    job on each pass, and a job's thirty modules would make that its main cost. Nothing is listed by hand.
    """
    key = (script, modules)
    if key not in _CODE:
        try:
            files = code_inputs(REPO / "workflow" / "scripts" / script, modules, REPO)
        except FileNotFoundError as err:
            raise WorkflowError(str(err)) from None
        _CODE[key] = {
            f.relative_to(REPO)
            .as_posix(): hashlib.sha256(f.read_bytes())
            .hexdigest()[:16]
            for f in files
        }
    return _CODE[key]


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
    if spec.source == "ycb" and spec.path is None:  # its package is not installed
        raise WorkflowError(f"{wildcards.object}: {MISSING_PACKAGES[0]}")
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


_CATALOG = {}  # (path, mtime) -> the catalog table


def catalog_frame():
    """The catalog checkpoint's table, read once per version of the file (input functions ask often)."""
    path = checkpoints.catalog.get().output[0]
    key = (path, os.stat(path).st_mtime_ns)
    if key not in _CATALOG:
        from tohgs.assets.objects import read_catalog

        _CATALOG.clear()
        _CATALOG[key] = read_catalog(path)
    return _CATALOG[key]


def accepted_objects(task):
    """Accepted objects of a task's set (bricks for stacking), read from the catalog checkpoint."""
    catalog = catalog_frame()
    return sorted(catalog[catalog.task_set == task_set(task)].name)


def task_targets(task):
    """The targets of ``task`` that have scene stores and task grasps: every accepted object of the task's set,
    or with an import its targets of the official train and val lists."""
    return IMPORTED.targets(task) if IMPORTED else accepted_objects(task)


def scene_stores_of(task):
    """Every scene store of ``task``."""
    return expand(
        "results/scenes/{task}/{object}.zarr", task=task, object=task_targets(task)
    )


def scene_stores(wildcards):
    return scene_stores_of(wildcards.task)


def scene_settings(wildcards):
    """The scenes settings one task uses (so another task's settings do not make it stale)."""
    keys = (
        "n_configs",
        "max_tries",
        "allow_fewer",
        "physics",
        "contact_margin",
        wildcards.task,
    )
    return _canonical({k: config["scenes"][k] for k in keys})


def prior_stores(wildcards):
    """The filtered prior-grasp store of every accepted object (objects and bricks)."""
    catalog = catalog_frame()
    return expand("results/grasps/prior/{object}.zarr", object=sorted(catalog.name))


def prior_screen(wildcards):
    """The filter thresholds that screen the grasps before SD (prior_grasps.simulate: screened), or None."""
    if config["prior_grasps"]["simulate"] != "screened":
        return None
    from tohgs.grasps.filter import SCREEN_KEYS

    return {k: config["prior_grasps"]["filter"][k] for k in SCREEN_KEYS}


def plane_direction(wildcards):
    """Support planes of the synthesis for this object's source (prior_grasps.plane_direction)."""
    return config["prior_grasps"]["plane_direction"][
        "bricks" if OBJECTS[wildcards.object].source == "bricks" else "objects"
    ]


SPLITS = ("train", "val", "test")


def split_objects(wildcards):
    """Accepted target objects of the task's set in the split (the catalog's split column); with an import, the
    official split of the task (train.txt, val.txt, the test JSONs)."""
    if IMPORTED:
        return IMPORTED.splits[wildcards.task][wildcards.split]
    catalog = catalog_frame()
    sel = catalog[
        (catalog.task_set == task_set(wildcards.task))
        & (catalog.split == wildcards.split)
    ]
    return sorted(sel.name)


def split_scene_stores(wildcards):
    """The split's scene stores; with an import, the test split's are the official test configurations."""
    folder = "test_scenes" if IMPORTED and wildcards.split == "test" else "scenes"
    return expand(
        f"results/{folder}/{{task}}/{{object}}.zarr",
        task=wildcards.task,
        object=split_objects(wildcards),
    )


def split_task_grasps(wildcards):
    """The split's task-grasp stores; none for an import's test split (its configurations have no grasps)."""
    if IMPORTED and wildcards.split == "test":
        return []
    return expand(
        "results/grasps/task/{task}/{object}.zarr",
        task=wildcards.task,
        object=split_objects(wildcards),
    )


def map_shards_of(task):
    """Every map shard of a task (all splits)."""
    return [
        f"results/maps/{task}/{split}/shard-{k}.zarr"
        for split in SPLITS
        for k in range(config["maps"]["shards"][split])
    ]


def all_map_shards(wildcards):
    return [p for task in config["scenes"]["tasks"] for p in map_shards_of(task)]


def all_scene_stores(wildcards):
    return [p for task in config["scenes"]["tasks"] for p in scene_stores_of(task)]


def all_task_grasps(wildcards):
    return [
        f"results/grasps/task/{task}/{o}.zarr"
        for task in config["scenes"]["tasks"]
        for o in task_targets(task)
    ]


if (
    IMPORTED
):  # the official test configurations have no task grasps: no method that reads them can run
    try:
        _dropped = drop_ground_truth_rows(
            config, "the official test configurations have no ground-truth grasps"
        )
    except ConfigError as err:
        raise WorkflowError(f"invalid configuration: {err}") from None
    if _dropped:
        print(
            f"official.import_dir: left out of the tables and figures (they read ground-truth grasps): "
            f"{', '.join(_dropped)}",
            file=sys.stderr,
        )

# Each method kind's declaration (tohgs.methods.kind_declarations).
KINDS = _SCHEMA["$defs"]["method_kinds"]
# The seed replicas (config key seeds): every table row's method, and what it builds on, once per seed
# but the first, as components and methods of their own (tohgs.config.add_seed_replicas).
REPLICAS = add_seed_replicas(
    config, [m for t in config["tables"].values() for m in t["rows"]], KINDS
)
SEED_OF = {
    r: seed for reps in REPLICAS.values() for r, seed in zip(reps, config["seeds"])
}
BASE_OF = {r: m for m, reps in REPLICAS.items() for r in reps}
COMPONENTS = config["components"]
METHODS = config["methods"]
TABLES = config["tables"]


def replicas_of(methods):
    """The methods with their seed replicas, each a map to its seed: the tables' and claims' param."""
    return {m: {r: SEED_OF[r] for r in REPLICAS.get(m, [m])} for m in methods}


def _names(names):
    """A wildcard constraint matching exactly ``names``."""
    return "|".join(re.escape(n) for n in sorted(names))


COMPONENT_NAME, METHOD_NAME, TABLE_NAME = (
    _names(COMPONENTS),
    _names(METHODS),
    _names(TABLES),
)


def used_methods():
    """The methods a table or the figures use, in first-use order: only these are predicted."""
    contact_figure = (
        [] if IMPORTED else config["figures"]["contact_methods"]
    )  # no contact maps' figure of an import
    names = [m for t in TABLES.values() for m in t["rows"]] + [
        *contact_figure,
        *config["figures"]["methods"],
    ]
    names += [m for ms in config["figures"]["comparisons"].values() for m in ms]
    out = []
    # with the methods whose predictions they read (F-GraspTTA's of), first
    for m in names:
        out += reversed(of_chain(m, METHODS, KINDS))
    return list(dict.fromkeys(out))


def components_of(method):
    """The components the method ``method`` names (:func:`tohgs.methods.method_components`)."""
    return method_components(METHODS[method], COMPONENTS)


def used_components():
    """The components of the used methods: only these are trained."""
    return list(dict.fromkeys(c for m in used_methods() for c in components_of(m)))


def component_settings(wildcards):
    """The training settings of one component: the training block overlaid with the component's own."""
    return _canonical(
        {**config["training"], **COMPONENTS[wildcards.component]["training"]}
    )


def method_settings(wildcards):
    """The prediction settings of one method's jobs, exactly those its kind reads (tohgs.config.job_settings:
    so a sampler setting leaves the dataset row's draw be; an optional block only when set).
    """
    return _canonical(job_settings(config, wildcards.method, _SCHEMA))


def figure_methods(wildcards):
    """The methods of a predictions figure: ``figures.methods``, or comparison ``name``'s of
    ``figures.comparisons`` (rule comparison_figure)."""
    name = wildcards.get("name")
    return (
        config["figures"]["methods"]
        if name is None
        else config["figures"]["comparisons"][name]
    )


def method_threads(wildcards):
    """A prediction job's cores: its method's ``settings.threads`` over ``prediction.threads`` (the job's
    torch threads: predict.py passes the cores Snakemake grants, at most these)."""
    return job_settings(config, wildcards.method, _SCHEMA)["threads"]


def method_block(wildcards):
    """The method's config block as its predictions depend on it: without its label (the tables' concern)."""
    return _canonical(
        {k: v for k, v in METHODS[wildcards.method].items() if k != "label"}
    )


# Job priorities (Snakemake's ``priority:``): the data stages first, then the trainings, then the predictions;
# the evaluation, tables and figures last. Without them the scheduler mixes stages freely on few cores, and
# one object's prior grasps, scheduled late, left a task's trainings to the last 4 of the smoke run's 11 minutes.
PRIORITY = {"data": 30, "train": 20, "predict": 10}


TORCH_RULES = ("prior_synthesis", "train", "predict")  # the rules that can run on a GPU


def rule_resources(name):
    """The cluster resources of the jobs of ``name``, a rule, from config ``resources``: its ``mem_mb`` and
    ``runtime``, and for the torch rules one GPU when the config asks for one (no ``gpu`` key otherwise,
    since the kubernetes plugin reads ``gpu=0`` as a request)."""
    r = dict(config["resources"]["rules"][name])
    if name in TORCH_RULES and config["resources"]["gpu"]:
        r.update(gpu=1, gpu_manufacturer=config["resources"]["gpu_manufacturer"])
    return r


def evaluation_sd_settings():
    """SD's settings in the evaluation: the physics of ``metrics.sd`` with the gravity of
    ``evaluation.sd_gravity`` (the prior grasps keep ``metrics.sd``'s own)."""
    return _canonical(evaluation_sd_settings_of(config))


def robust_sd_settings(wildcards):
    """Robust SD's settings for the method's evaluation: ``evaluation.robust_sd`` without its method list
    for a listed method; ``perturbations: 0`` (none) for the others, so their jobs do not rerun when the
    list or the perturbations change."""
    block = config["evaluation"]["robust_sd"]
    if BASE_OF.get(wildcards.method, wildcards.method) not in block["methods"]:
        return {"perturbations": 0}
    return _canonical({k: v for k, v in block.items() if k != "methods"})


def palm_sd_of(wildcards):
    """Whether the method's evaluation simulates SD out of the palm: ``evaluation.palm_sd`` true, or a list
    that names the method (or the method a seed replica is of)."""
    palm = config["evaluation"]["palm_sd"]
    return (
        palm
        if isinstance(palm, bool)
        else BASE_OF.get(wildcards.method, wildcards.method) in palm
    )


def method_models(wildcards):
    """The checkpoints of the method's components for the task."""
    return [
        f"results/models/{wildcards.task}/{c}.pt"
        for c in components_of(wildcards.method)
    ]


def method_base(wildcards):
    """The prediction store of the method whose predictions this one reads (its kind's key of role method:
    F-GraspTTA's of), or none."""
    base = base_method(wildcards.method, METHODS, KINDS)
    return [f"results/predictions/{wildcards.task}/{base}.zarr"] if base else []


def method_code(wildcards):
    """The code a prediction job of the method runs: the script's, the method kind's, its components' kinds'
    (:func:`code`)."""
    kinds = [f"methods/{METHODS[wildcards.method]['kind']}"]
    kinds += [
        f"models/{COMPONENTS[c]['kind']}" for c in components_of(wildcards.method)
    ]
    return code("predict.py", *kinds)


CHECKS_OF_KIND = component_checks()  # kind -> its schema block's x-checks


def checked_components():
    """The used components whose kinds declare checks (``x-checks``: the diffusers, ContactGen)."""
    return [c for c in used_components() if COMPONENTS[c]["kind"] in CHECKS_OF_KIND]


def train_shards(wildcards):
    return [
        f"results/maps/{wildcards.task}/train/shard-{k}.zarr"
        for k in range(config["maps"]["shards"]["train"])
    ]


def test_shards(wildcards):
    return [
        f"results/maps/{wildcards.task}/test/shard-{k}.zarr"
        for k in range(config["maps"]["shards"]["test"])
    ]


def prediction_outputs():
    """Every task's prediction store of every used method."""
    return [
        f"results/predictions/{task}/{m}.zarr"
        for task in config["scenes"]["tasks"]
        for m in used_methods()
    ]


def test_scene_stores(wildcards):
    """Scene stores of the task's test objects (the configurations the predictions are of)."""
    w = SimpleNamespace(task=wildcards.task, split="test")
    return split_scene_stores(w)


def all_test_shards(wildcards):
    return [
        p
        for task in config["scenes"]["tasks"]
        for p in test_shards(SimpleNamespace(task=task))
    ]


def table_metrics(wildcards):
    """Every task's metric file of every row of the table."""
    return [
        f"results/metrics/{task}/{r}.parquet"
        for task in config["scenes"]["tasks"]
        for m in TABLES[wildcards.table]["rows"]
        for r in REPLICAS[m]
    ]


def claims_methods():
    """The methods the claims compare: the rows of the tables they name."""
    return sorted(
        {m for c in config["claims"].values() for m in TABLES[c["table"]]["rows"]}
    )


def claims_metrics(wildcards):
    """Every task's metric file of every method the claims compare."""
    return [
        f"results/metrics/{task}/{r}.parquet"
        for task in config["scenes"]["tasks"]
        for m in claims_methods()
        for r in REPLICAS[m]
    ]


def viewer_methods():
    """The methods the viewer's static export draws: every table's rows (they are evaluated), in first-use order
    (the tables in the config's order: the built-in ones first, table1 to table5, then those a config file
    adds, such as config/extras.yaml's)."""
    return list(dict.fromkeys(m for t in TABLES.values() for m in t["rows"]))


def viewer_labels(wildcards):
    """The labels of the viewer's methods (their order is the export's)."""
    return {m: METHODS[m]["label"] for m in viewer_methods()}


def viewer_predictions(wildcards):
    return [f"results/predictions/{wildcards.task}/{m}.zarr" for m in viewer_methods()]


def viewer_metrics(wildcards):
    return [f"results/metrics/{wildcards.task}/{m}.parquet" for m in viewer_methods()]


def viewer_outputs():
    """The static viewer of every task, where the config asks for it (figures.viewer.export)."""
    if not config["figures"]["viewer"]["export"]:
        return []
    return [f"results/viewer/{task}.html" for task in config["scenes"]["tasks"]]


def claims_outputs():
    """The claims table, where the config has claims."""
    return ["results/tables/claims.csv"] if config["claims"] else []


def final_outputs():
    """The default target's outputs known before the catalog exists (see catalog_outputs)."""
    tasks = config["scenes"]["tasks"]
    return (
        [
            "results/objects/catalog.csv",
            "results/objects/supports",
            "results/figures/objects.png",
            "results/figures/hand.png",
            "results/maps/summary.csv",
            "results/figures/maps.png",
        ]
        + (
            []
            if IMPORTED
            else [  # an import has no prior grasps, and no truth for the contact maps' figure
                "results/grasps/prior/summary.csv",
                "results/figures/prior_grasps.png",
                "results/figures/contact_maps.png",
            ]
        )
        + [f"results/tables/{t}.csv" for t in TABLES]
        + claims_outputs()
        + prediction_outputs()
        + [
            f"results/models/{task}/checks.json"
            for task in tasks
            if checked_components()
        ]
        + [
            f"results/figures/{kind}_{task}.png"
            for task in tasks
            for kind in ("scenes", "predictions")
        ]
        + [
            f"results/figures/compare_{name}_{task}.png"
            for task in tasks
            for name in config["figures"]["comparisons"]
        ]
        + viewer_outputs()
    )


def catalog_outputs(wildcards):
    """The default target's outputs per accepted object, known once the catalog checkpoint has run."""
    return [
        store for task in config["scenes"]["tasks"] for store in scene_stores_of(task)
    ]


def hand_source(wildcards):
    """The user's MANO file when the mano backend is chosen (an input, so a new file reruns the hand)."""
    return [config["hand"]["mano_path"]] if config["hand"]["model"] == "mano" else []
