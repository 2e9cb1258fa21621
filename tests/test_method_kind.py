"""What a method kind and a component kind declare, and that a new method kind is its module and one schema
block: a kind defined in tests/method_kind_probe.py runs through the same validation, settings and prediction
as the built-in ones."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pytest

from tohgs.config import ConfigError, job_settings, load_schema, method_setting_keys, validate_config
from tohgs.methods import SAMPLING_KEYS, method_kinds, register_method_kind
from tohgs.methods.base import SamplingSettings


def test_each_method_kind_reads_exactly_its_schema_settings():
    """A kind's ``Settings`` and its schema block list the same settings: those every job reads, then its own."""
    from tohgs.methods.predict import method_class

    assert [f.name for f in dataclasses.fields(SamplingSettings)] == list(SAMPLING_KEYS)
    schema = load_schema()
    assert set(schema["$defs"]["method_kinds"]) == set(method_kinds())
    for kind in method_kinds():
        fields = [f.name for f in dataclasses.fields(method_class(kind).Settings)]
        assert sorted(fields) == sorted(method_setting_keys(kind, schema)), kind
    # F-GraspTTA samples what the config says (it read no samples, and took the dataclass's 16)
    cfg = validate_config({"prediction": {"samples": 2}})
    assert job_settings(cfg, "f-grasptta")["samples"] == 2
    assert "tta" not in job_settings(cfg, "f-grasptta") and "filter" not in job_settings(cfg, "grasptta")


def test_each_component_declares_the_role_of_its_schema_block():
    """The role a component class declares is its kind's ``x-role``; the registry knows only real kinds."""
    from tohgs.models import component_kind_exists, component_kinds
    from tohgs.models.component import component_class

    networks = load_schema()["$defs"]["networks"]
    assert set(component_kinds()) == set(networks)
    for kind in component_kinds():
        assert component_class(kind).role == networks[kind]["x-role"], kind
    assert not component_kind_exists("train") and not component_kind_exists("checkpoint")
    assert [k for k in component_kinds() if component_class(k).steerable] == ["contact_diffuser", "grasp_diffuser"]


def test_a_method_kind_is_its_module_and_one_schema_block(built, tmp_path, monkeypatch):
    import tohgs.methods
    from tests import method_kind_probe as probe
    from tohgs.data.maps import read_map_shard
    from tohgs.methods.predict import predict

    monkeypatch.setattr(tohgs.methods, "_REGISTERED", {})  # the registration ends with the test
    register_method_kind("lifted", "tests.method_kind_probe")
    with pytest.raises(ValueError, match="a kind of tohgs.methods"):
        register_method_kind("flex", "tests.method_kind_probe")
    schema = load_schema()
    schema["$defs"]["method_kinds"]["lifted"] = copy.deepcopy(probe.SCHEMA)
    cfg = {"methods": {"up": {"label": "Up", "kind": "lifted", "settings": {"lift": {"height": 0.02}}}},
           "prediction": {"samples": 3, "device": "cpu"}}
    validate_config(cfg, schema)
    assert cfg["prediction"]["lift"] == {"height": 0.01}  # the kind's block, with its default
    settings = job_settings(cfg, "up", schema)
    assert sorted(settings) == sorted([*SAMPLING_KEYS, "lift"]) and settings["lift"] == {"height": 0.02}
    shard = built[0] / "shard-0.zarr"
    up = predict("placing", "up", cfg["methods"]["up"], [shard], {}, settings, tmp_path / "up.zarr", complete=True)
    dataset = predict("placing", "dataset", {"kind": "reference"}, [shard], {},
                      job_settings(cfg, "dataset", schema), tmp_path / "dataset.zarr", complete=True)
    assert up["grasp_init"].shape == (read_map_shard(shard).n_configs, 3, 51)
    np.testing.assert_allclose(up["grasp_init"][..., 2], dataset["grasp_init"][..., 2] + 0.02, atol=1e-6)
    np.testing.assert_array_equal(up["grasp_init"][..., 3:], dataset["grasp_init"][..., 3:])

    # A setting the kind does not read is an error, in the config and in the job, and so is a missing one.
    bad = {"methods": {"up": {"label": "Up", "kind": "lifted", "settings": {"steps": 4}}}}
    with pytest.raises(ConfigError, match=r"'methods.up.settings.steps': a lifted method does not read it"):
        validate_config(bad, schema)
    with pytest.raises(ValueError, match=r"unknown settings \['tta'\]"):
        predict("placing", "up", cfg["methods"]["up"], [shard], {}, {**settings, "tta": {}}, tmp_path / "x.zarr")
    with pytest.raises(ValueError, match=r"settings \['lift'\] missing"):
        predict("placing", "up", cfg["methods"]["up"], [shard], {}, {k: v for k, v in settings.items() if k != "lift"},
                tmp_path / "y.zarr", complete=True)
    # Its block is its own: another kind may not claim it.
    schema["$defs"]["method_kinds"]["lifted_again"] = copy.deepcopy(probe.SCHEMA)
    with pytest.raises(ConfigError, match="prediction.lift is already method kind 'lifted'"):
        validate_config({}, schema)
