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
    roles = {n["x-role"] for n in schema["$defs"]["networks"].values()} | {"method"}
    prediction = schema["properties"]["prediction"]["properties"]
    for kind in method_kinds():
        fields = dataclasses.fields(method_class(kind).Settings)
        assert sorted(f.name for f in fields) == sorted(method_setting_keys(kind, schema)), kind
        for f in fields:  # a block the job may lack is optional in both places
            assert bool(f.metadata.get("optional")) == bool(prediction.get(f.name, {}).get("x-optional")), f.name
        decl = schema["$defs"]["method_kinds"][kind]
        for key, spec in decl["keys"].items():  # each key says what it names
            assert spec["role"] in roles and spec.get("description"), (kind, key)
    assert [k for k in method_kinds() if schema["$defs"]["method_kinds"][k].get("reads_ground_truth")] == ["reference"]
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
    from tohgs.models import component_checks
    from tohgs.models.checks import CHECKS

    checks = component_checks()
    assert set(checks) == {"contact_diffuser", "grasp_diffuser", "contact_gen"}
    assert {c for names in checks.values() for c in names} == set(CHECKS)  # each check declared, each known
    assert [k for k in component_kinds() if component_class(k).steerable] == ["contact_diffuser", "grasp_diffuser"]


def test_a_method_kind_is_its_module_and_one_schema_block(built, tmp_path, monkeypatch):
    """Kind ``lifted`` (tests/method_kind_probe.py) has a key of its own naming another method, reads ground
    truth and owns a settings block: registered with its block, it validates, gets its seed replicas and its
    jobs' settings, is dropped with the ground-truth rows, predicts from its base method's store and is a row
    of a table, with nothing of the library told about it but the registration."""
    import pandas as pd
    import trimesh

    import tohgs.methods
    from tests import method_kind_probe as probe
    from tohgs.assets.manifest import record_object_files
    from tohgs.config import add_seed_replicas, drop_ground_truth_rows
    from tohgs.data.maps import read_map_shard
    from tohgs.methods import of_chain, reads_ground_truth
    from tohgs.methods.predict import predict
    from tohgs.metrics.evaluate import evaluate_predictions
    from tohgs.metrics.tables import QualityThresholds, metric_table

    monkeypatch.setattr(tohgs.methods, "_REGISTERED", {})  # the registration ends with the test
    register_method_kind("lifted", "tests.method_kind_probe", probe.SCHEMA)
    with pytest.raises(ValueError, match="a kind of tohgs.methods"):
        register_method_kind("flex", "tests.method_kind_probe", probe.SCHEMA)
    up = {"label": "Up", "kind": "lifted", "lifts": "dataset", "settings": {"lift": {"height": 0.02}}}
    cfg = {"methods": {"up": up, "up-f": {"label": "Up, filtered", "kind": "filtered", "of": "up"}},
           "tables": {"lifted": {"rows": ["dataset", "up"], "columns": ["pv_avg", "qr", "grasps"]}},
           "prediction": {"samples": 3, "device": "cpu"}}
    validate_config(cfg)
    assert cfg["prediction"]["lift"] == {"height": 0.01}  # the kind's block, with its default
    settings = job_settings(cfg, "up")
    assert sorted(settings) == sorted([*SAMPLING_KEYS, "lift"]) and settings["lift"] == {"height": 0.02}
    methods = cfg["methods"]
    assert of_chain("up-f", methods) == ["up-f", "up", "dataset"]
    assert reads_ground_truth("up", methods) and reads_ground_truth("up-f", methods)
    replicas = add_seed_replicas(copy.deepcopy({**cfg, "seeds": [0, 1]}), ["up-f"])
    assert replicas["up"] == ["up", "up-seed1"] and replicas["dataset"] == ["dataset", "dataset-seed1"]
    seeded = copy.deepcopy({**cfg, "seeds": [0, 1]})
    add_seed_replicas(seeded, ["up"])
    assert seeded["methods"]["up-seed1"]["lifts"] == "dataset-seed1"  # its key follows the seed
    dropped = copy.deepcopy(cfg)
    dropped["tables"]["lifted"]["rows"].append("grasptta")
    assert drop_ground_truth_rows(dropped, "no ground truth")[:2] == ["dataset", "up"]

    # A key it does not declare, a missing one, a base that is not a method, a setting it does not read.
    for bad, problem in [({**up, "of": "dataset"}, r"'methods.up.of': not a key of a lifted method \(its keys: "
                                                   r"label, kind, settings, lifts\)"),
                         ({k: v for k, v in up.items() if k != "lifts"}, "'methods.up.lifts': required"),
                         ({**up, "lifts": "nothing"}, "'methods.up.lifts': 'nothing' is not another method"),
                         ({**up, "settings": {"steps": 4}}, r"'methods.up.settings.steps': a lifted method does "
                                                            "not read it")]:
        with pytest.raises(ConfigError, match=problem):
            validate_config({"methods": {"up": bad}})

    tmp, hand = built[0], built[1]
    shard = tmp / "shard-0.zarr"
    dataset = predict("placing", "dataset", methods["dataset"], [shard], {}, job_settings(cfg, "dataset"),
                      tmp_path / "dataset.zarr", complete=True)
    with pytest.raises(ValueError, match="lifting needs the predictions of 'dataset'"):
        predict("placing", "up", up, [shard], {}, settings, tmp_path / "x.zarr", complete=True)
    lifted = predict("placing", "up", up, [shard], {}, settings, tmp_path / "up.zarr", base=tmp_path / "dataset.zarr",
                     hand=None, complete=True)
    assert lifted["grasp_init"].shape == (read_map_shard(shard).n_configs, 3, 51)
    np.testing.assert_allclose(lifted["grasp_init"][..., 2], dataset["grasp_init"][..., 2] + 0.02, atol=1e-6)
    np.testing.assert_array_equal(lifted["grasp_init"][..., 3:], dataset["grasp_init"][..., 3:])
    with pytest.raises(ValueError, match=r"unknown settings \['tta'\]"):
        predict("placing", "up", up, [shard], {}, {**settings, "tta": {}}, tmp_path / "y.zarr")
    with pytest.raises(ValueError, match=r"settings \['lift'\] missing"):
        predict("placing", "up", up, [shard], {}, {k: v for k, v in settings.items() if k != "lift"},
                tmp_path / "z.zarr", complete=True)

    # In a table: both rows evaluated as the workflow does, the lifted hands 2 cm off the cube (none in it).
    mesh = trimesh.load(tmp / "objects/brick-cube/mesh.obj", force="mesh")
    mesh.export(tmp / "objects/brick-cube/collision.obj")  # the cube is convex: its own decomposition
    record_object_files(tmp / "objects/brick-cube", {"name": "brick-cube"}, ["mesh.obj", "collision.obj"])
    rows = pd.concat([evaluate_predictions(tmp_path / f"{m}.zarr", [tmp / "scenes/brick-cube.zarr"], tmp / "objects",
                                           tmp / "objects/supports/supports.json", hand.assets,
                                           {"gravity_direction": "fixed"}) for m in ("dataset", "up")])
    table = cfg["tables"]["lifted"]
    t = metric_table(rows.assign(seed=0), ["placing"], table["rows"], {m: methods[m]["label"] for m in methods},
                     table["columns"], QualityThresholds())
    assert list(t.method) == ["Dataset", "Up"] and list(t.grasps) == [6, 6]
    assert (rows[rows.method == "up"].contact_distance.to_numpy()
            > rows[rows.method == "dataset"].contact_distance.to_numpy() + 0.015).all()

    # Its block is its own: another kind may not claim it.
    schema = load_schema()
    schema["$defs"]["method_kinds"]["lifted_again"] = copy.deepcopy(probe.SCHEMA)
    with pytest.raises(ConfigError, match="prediction.lift is already method kind 'lifted'"):
        validate_config({}, schema)
    # Nor may a kind read the predictions of two methods.
    two = copy.deepcopy(probe.SCHEMA)
    two["keys"]["also"] = {"role": "method", "description": "A second base."}
    schema = load_schema()
    schema["$defs"]["method_kinds"]["lifted"] = two
    with pytest.raises(ConfigError, match="lifts, also all name a method"):
        validate_config({}, schema)


def test_the_config_guide_names_every_kind_and_its_keys(repo):
    """config/README.md's methods section follows the declarations: every kind of the package and each of
    its keys is named there (a kind or key added to the schema and not documented fails)."""
    text = (repo / "config" / "README.md").read_text()
    section = text[text.index("## `methods`, `prediction`"):text.index("## `tables`")]
    kinds = load_schema()["$defs"]["method_kinds"]
    for kind in method_kinds():
        assert f"`{kind}`" in section, kind
        for key in kinds[kind]["keys"]:
            assert f"`{key}`" in section, (kind, key)
