"""Config validation: schema completeness, defaults, and errors that name the key and the problem."""

from __future__ import annotations

import copy
import subprocess
import sys

import pytest
import yaml

from tohgs.config import ConfigError, _deep_update, iter_schema_keys, load_schema, validate_config


def test_every_schema_key_has_description_and_default():
    schema = load_schema()
    keys = list(iter_schema_keys(schema))
    assert len(keys) > 30
    for parts, sub in keys:
        assert "description" in sub, f"{'.'.join(parts)} has no description"
        assert "default" in sub, f"{'.'.join(parts)} has no default"


def test_schema_defaults_equal_the_embedded_default(default_config):
    filled = validate_config({})
    assert validate_config(default_config) == filled


@pytest.mark.parametrize("path", ["config/config.yaml", "config/paper.yaml", ".test/config/config.yaml"])
def test_shipped_configs_validate(repo, path):
    with open(repo / path) as fh:
        validate_config(yaml.safe_load(fh), base_dir=repo)


def test_defaults_are_filled_in_place():
    cfg = {"objects": {"sources": {"bricks": {"count": 5}}}}
    validate_config(cfg)
    assert cfg["objects"]["sources"]["bricks"] == {"count": 5, "scale": 1.0}
    assert cfg["objects"]["size"]["longest_max"] == 0.16


@pytest.mark.parametrize(
    ("patch", "key", "problem"),
    [
        ({"objects": {"density": "heavy"}}, "objects.density", "expected number"),
        ({"objects": {"sources": {"bricks": {"count": 30}}}}, "objects.sources.bricks.count", "out of range"),
        ({"objects": {"size": {"longest_min": -0.1}}}, "objects.size.longest_min", "out of range"),
        ({"objects": {"colour": "red"}}, "objects.colour", "unknown key"),
        ({"sed": 1}, "sed", "unknown key"),
        ({"hand": {"model": "smplx"}}, "hand.model", "is not one of"),
        ({"hand": {"model": "mano"}}, "hand.mano_path", "required"),
        ({"hand": {"model": "mano", "mano_path": "no/MANO_RIGHT.pkl"}}, "hand.mano_path", "does not exist"),
        ({"objects": {"size": {"longest_min": 0.2, "longest_max": 0.1}}}, "objects.size.longest_min", "larger than"),
        ({"objects": {"sources": {"dir": {"path": "no/such/folder"}}}}, "objects.sources.dir.path", "does not exist"),
        ({"objects": {"sources": {"pybullet_data": {"random_urdfs": 0, "named": 0}, "bricks": {"count": 0}}}},
         "objects.sources", "empty"),
    ],
)
def test_invalid_config_names_key_and_problem(default_config, patch, key, problem):
    cfg = copy.deepcopy(default_config)
    _deep_update(cfg, patch)
    with pytest.raises(ConfigError) as exc:
        validate_config(cfg)
    msg = str(exc.value)
    assert f"'{key}'" in msg and problem in msg, msg


def test_invalid_config_stops_the_workflow_before_any_job(repo, tmp_path):
    """A bad setting on the command line makes Snakemake fail at parse time, naming the key."""
    out = subprocess.run(
        [sys.executable, "-m", "snakemake", "-s", str(repo / "workflow" / "Snakefile"), "--directory",
         str(tmp_path), "--configfile", str(repo / ".test" / "config" / "config.yaml"), "--cores", "1",
         "--config", "seed=-3"],
        capture_output=True, text=True, timeout=120)
    assert out.returncode != 0
    assert "config key 'seed'" in out.stderr + out.stdout and "out of range" in out.stderr + out.stdout
    assert not (tmp_path / "results").exists(), "a job ran despite the invalid config"

