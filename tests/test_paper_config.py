"""config/paper.yaml checked: the size of its DAG per rule, past the catalog checkpoint (issue 22).

A plain dry run of the paper config shows only the jobs known before the ``catalog`` checkpoint has run:
the per-object jobs (scenes, prior grasps, task grasps) appear once ``results/objects/catalog.csv``
exists and is up to date. So, in a copy of the workflow in a temporary folder, the test dry-runs the
config once as it is (every object job and the checkpoint to run), then lays down what the objects stage
would have left: one folder per selected object with a ``meta.json`` (status ``ok``: every object
accepted, so the counts are the upper bound a real run reaches when validation rejects none) and the
catalog written from them by the checkpoint's own function (:func:`tohgs.assets.objects.write_catalog`,
the real format and split), with modification times in data-flow order (source meshes < object folders <
catalog). No Snakemake metadata exists for them, so the params and code triggers have nothing to compare
and Snakemake takes the checkpoint as done: a second dry run lists every job after it. The expected count
of every rule is derived here from the config's values (objects, tasks, shards, tables, methods, seeds),
not from the workflow's helpers, so a change of config/paper.yaml keeps the test meaningful. The counts
are in docs/scale.md.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
import yaml
from workflow_tools import copy_workflow, job_stats, workflow_env
from tohgs.methods import of_chain
from tohgs.models import component_checks

REPO = Path(__file__).resolve().parent.parent
PAPER = "config/paper.yaml"
pytestmark = pytest.mark.slow  # two dry runs of the paper config: about 25 s each on 2 cores


def _dry_run(workdir: Path) -> dict[str, int]:
    cmd = [sys.executable, "-m", "snakemake", "--cores", "2", "--configfile", PAPER, "-n", "--quiet", "rules"]
    out = subprocess.run(cmd, cwd=workdir, capture_output=True, text=True, timeout=600, env=workflow_env(workdir),
                         stdin=subprocess.DEVNULL)  # a dry run reads no stdin
    text = out.stdout + out.stderr
    assert out.returncode == 0, text[-3000:]
    return job_stats(text)


def _paper_config() -> dict:
    """The paper config as the workflow sees it: the file over the schema's defaults."""
    from tohgs.config import validate_config

    return validate_config(yaml.safe_load((REPO / PAPER).read_text()), base_dir=REPO)


def _write_catalog(workdir: Path, cfg: dict) -> pd.DataFrame:
    """Every selected object's folder with an accepted ``meta.json``, then the catalog written from them,
    with modification times in data-flow order; returns the catalog table."""
    from tohgs.assets.objects import write_catalog
    from tohgs.assets.sources import select_objects, task_set

    specs = select_objects(cfg["objects"], cfg["seed"], base_dir=workdir)
    objects = workdir / "results/objects"
    dirs = []
    for spec in specs:
        d = objects / spec.name
        d.mkdir(parents=True)
        (d / "meta.json").write_text(json.dumps({"name": spec.name, "source": spec.source,
                                                 "task_set": spec.task_set, "status": "ok", "path": spec.path}))
        dirs.append(d)
    catalog = objects / "catalog.csv"
    task_sets = sorted({task_set(t) for t in cfg["scenes"]["tasks"]})
    table = write_catalog(dirs, cfg["objects"]["split"], cfg["seed"], catalog, task_sets=task_sets)
    now = time.time()
    for spec, d in zip(specs, dirs):
        assert spec.path is None or os.stat(spec.path).st_mtime < now - 60  # the sources are older
        os.utime(d / "meta.json", (now - 60, now - 60))
        os.utime(d, (now - 60, now - 60))
    os.utime(catalog, (now - 30, now - 30))
    return table


@pytest.fixture(scope="module")
def paper_dag(tmp_path_factory) -> dict:
    """The paper config's jobs before and after the catalog checkpoint, the config and the catalog."""
    work = copy_workflow(tmp_path_factory.mktemp("paper"))
    cfg = _paper_config()
    before = _dry_run(work)
    catalog = _write_catalog(work, cfg)
    after = _dry_run(work)
    return {"before": before, "after": after, "config": cfg, "catalog": catalog}


def _components_of(method: dict, components: dict) -> list[str]:
    """The components a method block names (any value but its label, kind and settings)."""
    return [v for k, v in method.items() if k not in ("label", "kind", "settings") and v in components]


def _with_bases(names: list[str], methods: dict) -> list[str]:
    """The methods with those whose predictions they read (F-GraspTTA's ``of``), each once."""
    return list(dict.fromkeys(b for m in names for b in of_chain(m, methods)))


def _expected(cfg: dict) -> dict[str, dict[str, int]]:
    """Each rule's job count before and after the checkpoint, from the config's values alone."""
    src = cfg["objects"]["sources"]
    n_objects = src["pybullet_data"]["random_urdfs"] + src["pybullet_data"]["named"] + src["ycb"]["count"]
    n_bricks = src["bricks"]["count"]
    assert src["dir"]["path"] is None  # a user folder would add its files
    tasks = cfg["scenes"]["tasks"]
    targets = {"placing": n_objects, "shelving": n_objects, "stacking": n_bricks}  # each task's target set
    seeds = len(cfg["seeds"])
    methods, components, tables = cfg["methods"], cfg["components"], cfg["tables"]
    rows = list(dict.fromkeys(m for t in tables.values() for m in t["rows"]))
    figures = cfg["figures"]["methods"] + cfg["figures"]["contact_methods"]
    replicated = _with_bases(rows, methods)  # every seed trains and predicts these
    first_seed = _with_bases(rows + figures, methods)  # the first seed also the figures' methods

    def comps(names):
        return {c for m in names for c in _components_of(methods[m], components)}

    n_train = len(comps(first_seed)) + (seeds - 1) * len(comps(replicated))
    n_predict = len(first_seed) + (seeds - 1) * len(replicated)
    checked = {c for c in comps(first_seed) if components[c]["kind"] in component_checks()}
    every_time = {  # the jobs known before the checkpoint, in both dry runs (nothing exists yet)
        "hand_model": 1, "supports": 1, "hand_figure": 1, "objects_figure": 1, "prior_figure": 1,
        "prior_summary": 1, "scenes_figure": len(tasks), "dataset_summary": 1, "maps_figure": 1,
        "maps": len(tasks) * sum(cfg["maps"]["shards"].values()),
        "train": len(tasks) * n_train,
        "predict": len(tasks) * n_predict,
        "evaluate": len(tasks) * len(rows) * seeds,  # the tables' and claims' rows, every seed
        "model_checks": len(tasks) if checked else 0,
        "contact_maps_figure": 1, "predictions_figure": len(tasks), "table": len(tables),
        "claims": 1 if cfg["claims"] else 0, "all": 1,
        "viewer": len(tasks) if cfg["figures"]["viewer"]["export"] else 0,
    }
    per_object = {  # the jobs the catalog reveals: per accepted object and per task and target object
        "scenes": sum(targets[t] for t in tasks),
        "prior_synthesis": n_objects + n_bricks,
        "prior_filter": n_objects + n_bricks,
        "task_grasps": sum(targets[t] for t in tasks),
    }
    before = {**every_time, "prepare_object": n_objects + n_bricks, "catalog": 1}
    after = {**every_time, **per_object}
    return {k: {r: n for r, n in v.items() if n} for k, v in (("before", before), ("after", after))}


def test_the_paper_config_is_the_papers_scale(paper_dag):
    """The absolute sizes of the paper (REFERENCE.md): 104 objects with 21 unseen test objects, 23 bricks
    with 6 unseen test bricks, three tasks, three seeds, the 64/8/8 map shards."""
    cfg, cat = paper_dag["config"], paper_dag["catalog"]
    assert cfg["scenes"]["tasks"] == ["placing", "stacking", "shelving"] and len(cfg["seeds"]) == 3
    objects, bricks = cat[cat.task_set != "stacking"], cat[cat.task_set == "stacking"]
    assert len(objects) == 104 and (objects.split == "test").sum() == 21
    assert len(bricks) == 23 and (bricks.split == "test").sum() == 6
    assert (cat.status == "ok").all() and set(cat.split) == {"train", "val", "test"}
    assert cfg["maps"]["shards"] == {"train": 64, "val": 8, "test": 8}


def test_before_the_catalog_only_the_objects_jobs_and_the_known_outputs(paper_dag):
    want = _expected(paper_dag["config"])["before"]
    assert paper_dag["before"] == want
    assert want["prepare_object"] == 127 and want["catalog"] == 1


def test_past_the_catalog_every_per_object_job(paper_dag):
    """With the checkpoint done, the per-object jobs appear and the objects' jobs are gone."""
    got = paper_dag["after"]
    assert got == _expected(paper_dag["config"])["after"]
    # absolute numbers of the paper's scale: 2 x 104 + 23 scenes and task-grasp jobs, 127 prior-grasp
    # jobs, 3 x 80 shards, 9 components and 12 methods x 3 seeds x 3 tasks
    assert got["scenes"] == got["task_grasps"] == 231 and got["prior_synthesis"] == got["prior_filter"] == 127
    assert got["maps"] == 240 and got["train"] == 81 and got["predict"] == got["evaluate"] == 108
    assert "prepare_object" not in got and "catalog" not in got
