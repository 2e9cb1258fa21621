"""Config validation: schema completeness, defaults, and errors that name the key and the problem."""

from __future__ import annotations

import copy
import subprocess
import sys

import pytest
import yaml

from tohgs.config import ConfigError, iter_schema_keys, load_schema, validate_config
from tohgs.settings import merge


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
        ({"objects": {"sources": {"pybullet_data": {"random_urdfs": 0, "named": 0}, "bricks": {"count": 0},
                                  "ycb": {"count": 0}}}}, "objects.sources", "empty"),
        ({"components": {"flow": {"kind": "flow_matcher"}}}, "components.flow.kind", "unknown component kind"),
        ({"components": {"My Net": {"kind": "grasp_diffuser"}}}, "components", "does not match"),
        ({"components": {"contact_diffuser": {"network": {"d_modle": 8}}}}, "components.contact_diffuser.network.d_modle",
         "unknown key"),
        ({"components": {"grasp_diffuser": {"training": {"step": 3}}}}, "components.grasp_diffuser.training.step",
         "unknown key"),
        ({"methods": {"ours": {"contact": "contact_difuser"}}}, "methods.ours.contact", "is not a component"),
        ({"methods": {"ours": {"contact": "grasp_diffuser"}}}, "methods.ours.contact", "is a grasp component"),
        ({"methods": {"x": {"label": "X", "kind": "contact_grasp", "contact": "ground_truth"}}}, "methods.x.grasp",
         "required"),
        ({"methods": {"x": {"label": "X", "kind": "retrieval"}}}, "methods.x.kind", "unknown method kind"),
        ({"methods": {"ours": {"settings": {"sampler": "euler"}}}}, "methods.ours.settings.sampler", "is not one of"),
        ({"methods": {"Ours": {"label": "X", "kind": "reference"}}}, "methods", "does not match"),
        ({"tables": {"table1": {"rows": ["dataset", "oracle"]}}}, "tables.table1.rows", "is not a method"),
        ({"tables": {"t2": {"rows": ["ours"], "columns": ["tss"]}}}, "tables.t2.columns.0", "is not one of"),
        ({"figures": {"contact_methods": ["ours", "oracle"]}}, "figures.contact_methods", "is not a method"),
        ({"figures": {"methods": ["ours", "oracle"]}}, "figures.methods", "is not a method"),
        ({"evaluation": {"palm_sd": ["ours", "oracle"]}}, "evaluation.palm_sd", "is not a method"),
        ({"evaluation": {"palm_sd": "ours"}}, "evaluation.palm_sd", "expected ['boolean', 'array']"),
        ({"methods": {"grasptta": {"contact_net": "contact_diffuser"}}}, "methods.grasptta.contact_net",
         "must be a hand_contact component"),
        ({"methods": {"grasptta": {"contact": "nothing"}}}, "methods.grasptta.contact", "is not a component"),
        ({"methods": {"f-grasptta": {"settings": {"filter": {"transform": "ransac"}}}}},
         "methods.f-grasptta.settings.filter.transform", "is not one of"),
        ({"methods": {"f-grasptta": {"settings": {"filter": {"max_op": 0.1}}}}}, "methods.f-grasptta.settings.filter.max_op",
         "unknown key"),
        ({"tables": {"table2": {"pending": [{"label": "X"}]}}}, "tables.table2.pending.0", "required"),
        ({"methods": {"f-grasptta": {"of": "f-grasptta"}}}, "methods.f-grasptta.of", "is not another method"),
        ({"methods": {"a": {"label": "A", "kind": "filtered", "of": "b"}, "b": {"label": "B", "kind": "filtered", "of": "a"}}},
         "methods.a.of", "a cycle of methods"),
    ],
)
def test_invalid_config_names_key_and_problem(default_config, patch, key, problem):
    cfg = copy.deepcopy(default_config)
    merge(cfg, patch)
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



def test_a_config_adds_methods_and_tables_to_the_built_in_ones_and_fills_their_defaults():
    cfg = validate_config({"methods": {"ours-ddpm": {"label": "Ours (DDPM)", "kind": "contact_grasp",
                                                     "contact": "contact_diffuser", "grasp": "grasp_diffuser",
                                                     "settings": {"sampler": "ddpm"}}},
                           "tables": {"samplers": {"rows": ["ours", "ours-ddpm"]}},
                           "components": {"grasp_diffuser": {"kind": "grasp_diffuser", "network": {"d_model": 32}}}})
    assert set(cfg["methods"]) == {"dataset", "ours", "ours-gt-contact", "grasptta", "f-grasptta", "m-grasptta-ta",
                                   "m-grasptta-gt", "m-grasptta-oc", "contactgen", "cc-gd", "scenediffuser",
                                   "flex", "ours-ddpm"}
    assert set(cfg["tables"]) == {"table1", "table2", "table4", "table5", "samplers"}
    assert cfg["tables"]["samplers"]["columns"][-1] == "discarded" and cfg["tables"]["samplers"]["pending"] == []
    gd = cfg["components"]["grasp_diffuser"]
    # a built-in entry overlaid: the keys the config does not give come from the built-in one
    assert gd["network"]["d_model"] == 32 and gd["network"]["n_blocks"] == 3 and gd["training"]["steps"] == 2400
    assert cfg["components"]["contact_diffuser"]["training"] == {"steps": 800, "batch": 16, "train_points": 0,
                                                                  "clip_grad": 0.0}  # the built-in entry


#: The settings dataclasses that are no kind's (a kind's are found through its module: its ``Settings``, its
#: ``Config`` and their blocks), by the config block they mirror.
SETTINGS_BLOCKS = {
    "tohgs.models.train.TrainSettings": ("training",),
    "tohgs.metrics.bootstrap.BootstrapSettings": ("evaluation", "bootstrap"),
    "tohgs.metrics.quality_thresholds.QualityThresholds": ("evaluation", "qr"),
    "tohgs.assets.mesh.MeshLimits": ("objects", "limits"),
    "tohgs.assets.decomposition.DecompositionSettings": ("objects", "decomposition"),
    "tohgs.sim.world.PhysicsSettings": ("scenes", "physics"),
    "tohgs.grasps.prior.SDFSettings": ("prior_grasps", "sdf"),
    "tohgs.metrics.quality.SDSettings": ("metrics", "sd"),
    "tohgs.data.build_maps.MapSettings": ("maps", "points"),
    "tohgs.grasps.expand.ExpansionSettings": ("task_grasps",),
    "tohgs.geometry.registration.ICPSettings": ("prediction", "filter", "icp"),
}
#: Settings dataclasses that mirror no config block as they stand, and why.
NOT_CONFIG_BLOCKS = {
    "tohgs.metrics.quality.RobustSDSettings": "evaluation.robust_sd is off for a method it does not list; the "
                                             "library's default, 0 perturbations, is that off",
    "tohgs.grasps.synthesis.SynthesisSettings": "the library's default is DexGraspNet's synthesis, no support "
                                                "planes (plane_fraction 0); the workflow's planes are set per "
                                                "object source (prior_grasps.plane_direction)",
    "tohgs.grasps.filter.FilterThresholds": "the library's defaults are DexGraspNet's thresholds (config/paper.yaml); "
                                            "the workflow's default relaxes max_fc, max_dis and max_pen (the schema "
                                            "says why)",
    "tohgs.models.diffusion.DiffusionConfig": "read from a network's diffusion mapping, which each diffuser's "
                                              "Config holds whole as its default (compared there)",
    "tohgs.models.pointnet2.PointNet2Config": "built from a network's pointnet mapping with the channels the model "
                                              "sets; each network's Config holds the mapping (compared there)",
}


def _settings_dataclasses() -> set[str]:
    """Every settings dataclass of the library (a public class named ``*Settings``, ``*Config``, ``*Limits`` or
    ``*Thresholds``), by dotted name, every module imported."""
    import dataclasses
    import importlib
    import inspect
    import pkgutil

    import tohgs

    found = set()
    for info in pkgutil.walk_packages(tohgs.__path__, "tohgs."):
        if info.name.endswith("__main__"):
            continue
        module = importlib.import_module(info.name)
        for name, obj in inspect.getmembers(module, inspect.isclass):
            if (obj.__module__ == info.name and dataclasses.is_dataclass(obj) and not name.startswith("_")
                    and name.endswith(("Settings", "Config", "Limits", "Thresholds"))):
                found.add(f"{info.name}.{name}")
    return found


def test_the_settings_dataclasses_default_to_the_schema():
    """One source of truth: a library default that differs from the schema's is a test failure. Every
    settings dataclass is compared: each kind's (its ``Settings`` or ``Config`` and their blocks, found
    through the kinds), the others by the block they mirror; a new one that is neither fails."""
    import dataclasses
    import importlib

    from tohgs.config import _fill_defaults
    from tohgs.methods import method_kinds
    from tohgs.methods.predict import method_class
    from tohgs.models import component_kinds
    from tohgs.models.component import component_class

    cfg = validate_config({})
    schema = load_schema()
    compared: set[str] = set()
    norm = (lambda v: [norm(x) for x in v] if isinstance(v, (list, tuple)) else v)  # noqa: E731

    def compare(cls: type, block: dict) -> None:
        compared.update(f"{c.__module__}.{c.__qualname__}" for c in cls.__mro__ if dataclasses.is_dataclass(c))
        for f in dataclasses.fields(cls):
            value = getattr(cls(), f.name)
            assert f.name in block, f"{cls.__name__}.{f.name} is not in the schema"
            sub = f.metadata.get("block") or (type(value) if dataclasses.is_dataclass(value) else None)
            if sub is not None:  # a block: its own dataclass
                compare(sub, block[f.name])
            elif isinstance(block[f.name], dict) and value in ({}, None):
                continue  # a plain mapping compared by the dataclass that reads it
            else:
                assert norm(value) == norm(block[f.name]), f"{cls.__name__}.{f.name}: {value!r} != schema {block[f.name]!r}"

    for kind in method_kinds():
        compare(method_class(kind).Settings, cfg["prediction"])
    for kind in component_kinds():
        network: dict = {}
        _fill_defaults(network, schema["$defs"]["networks"][kind])
        compare(component_class(kind).Config, network)
    for dotted, path in SETTINGS_BLOCKS.items():
        module, name = dotted.rsplit(".", 1)
        block = cfg
        for key in path:
            block = block[key]
        compare(getattr(importlib.import_module(module), name), block)
    missing = _settings_dataclasses() - compared - set(NOT_CONFIG_BLOCKS)
    assert not missing, f"settings dataclasses compared with no config block: {sorted(missing)}"


def test_every_network_key_has_description_and_default():
    schema = load_schema()
    for kind, sub in schema["$defs"]["networks"].items():
        for parts, leaf in iter_schema_keys(sub):
            assert "description" in leaf and "default" in leaf, f"$defs.networks.{kind}.{'.'.join(parts)}"


def test_an_import_without_ground_truth_leaves_out_exactly_the_rows_that_read_it(default_config, repo):
    """drop_ground_truth_rows: the Dataset row (kind reference), the GT-contact rows (contact: ground_truth)
    and a filtered method of one of them become pending rows with the reason, under the table's own label;
    every other row stays, in order; a table of ground-truth rows only is refused."""
    from tohgs.config import drop_ground_truth_rows
    from tohgs.methods import reads_ground_truth

    cfg = copy.deepcopy(default_config)
    with open(repo / "config/extras.yaml") as fh:  # the ContactGen gate's method and table
        merge(cfg, yaml.safe_load(fh))
    validate_config(cfg)  # the defaults filled in
    cfg["methods"]["f-gt"] = {"label": "F-GT", "kind": "filtered", "of": "m-grasptta-gt", "settings": {}}
    cfg["tables"]["table2"]["rows"].append("f-gt")
    cfg["figures"]["comparisons"] = {"gt": ["dataset"], "mixed": ["ours", "ours-gt-contact"]}
    assert {m for m in cfg["methods"] if reads_ground_truth(m, cfg["methods"])} == {
        "dataset", "ours-gt-contact", "m-grasptta-gt", "contactgen-gt", "ours-gt-thumb", "ours-gt-refined", "f-gt"}
    dropped = drop_ground_truth_rows(cfg, "no truth here")
    assert dropped == ["dataset", "ours-gt-contact", "contactgen-gt", "ours-gt-thumb", "ours-gt-refined", "m-grasptta-gt",
                       "f-gt"]  # in the tables' order
    assert cfg["tables"]["table_contactgen_gate"]["rows"] == ["contactgen"]
    assert cfg["tables"]["table1"]["rows"] == ["grasptta", "f-grasptta", "contactgen", "scenediffuser", "flex", "ours"]
    assert cfg["tables"]["table1"]["pending"] == [{"label": "Dataset", "reason": "no truth here"},
                                                  {"label": "Ours (GT contact)", "reason": "no truth here"}]
    assert cfg["tables"]["table2"]["rows"] == ["m-grasptta-oc", "m-grasptta-ta", "cc-gd", "ours"]
    assert [p["label"] for p in cfg["tables"]["table2"]["pending"]] == ["M-GraspTTA (GT)", "Ours (GT)", "F-GT"]
    assert cfg["tables"]["table4"]["rows"] == ["m-grasptta-ta", "ours"]
    assert cfg["figures"]["comparisons"] == {"mixed": ["ours"]}
    cfg["tables"]["truth"] = {"rows": ["dataset"], "pending": []}
    with pytest.raises(ConfigError, match="tables.truth.rows"):
        drop_ground_truth_rows(cfg, "no truth here")


EXTRA_COLUMNS = {"sd_robust", "sd_pass", "sd_unstable", "sd_palm_avg", "qr_palm"}


def _overlaid(repo, *files: str) -> dict:
    """The validated config of config/config.yaml with the given overlays (paths from the repository root)."""
    with open(repo / "config/config.yaml") as fh:
        cfg = yaml.safe_load(fh) or {}
    for f in files:
        with open(repo / f) as fh:
            merge(cfg, yaml.safe_load(fh))
    return validate_config(cfg, base_dir=repo)


def test_the_default_has_no_extras_and_the_extras_overlay_adds_them_all(repo):
    """The beyond-paper diagnostics (robust SD, palm SD, ContactGen's gate, ContactGen in SO(3), ContactCVAE near
    the initial pose) are out of the default run: no method is listed for them, no table has their rows or
    columns; config/extras.yaml adds every one, and keeps Table 1's rows."""
    default, extras = _overlaid(repo), _overlaid(repo, "config/extras.yaml")
    ev = default["evaluation"]
    assert ev["palm_sd"] is False and ev["robust_sd"]["methods"] == []
    assert not {"contactgen-gt", "contactgen-so3", "cc-gd-bounded", "m-grasptta-oc-bounded"} & set(default["methods"])
    assert not {"table_contactgen_gate", "table_contactgen_rotation", "table_contactcvae_rotation"} & set(default["tables"])
    assert not any(EXTRA_COLUMNS & set(t["columns"]) for t in default["tables"].values())
    ev = extras["evaluation"]
    assert ev["palm_sd"] == ["dataset", "ours"] and ev["robust_sd"]["methods"] == ["dataset", "ours"]
    assert EXTRA_COLUMNS <= set(extras["tables"]["table1"]["columns"])
    assert extras["tables"]["table1"]["rows"] == default["tables"]["table1"]["rows"]
    assert extras["tables"]["table_contactgen_gate"]["rows"] == ["dataset", "contactgen-gt", "contactgen"]
    assert extras["tables"]["table_contactgen_rotation"]["rows"] == ["contactgen", "contactgen-so3"]
    assert extras["components"]["contact_gen_so3"]["training"]["rotation"] == "so3"
    assert default["components"]["contact_gen"]["training"]["rotation"] == "bounded"  # ContactGen's own recipe
    # ContactCVAE in SO(3) as the paper's OC rows behave (they collide at the initial pose as often as at the
    # goal); the variant that learns "up" near the initial pose is the extras' row of both OC methods
    assert default["components"]["contact_cvae"]["training"]["rotation"] == "so3"
    bounded = extras["components"]["contact_cvae_bounded"]
    assert bounded["training"]["rotation"] == "bounded" and bounded["network"]["parts"] is False
    assert {extras["methods"][m]["contact"] for m in ("cc-gd-bounded", "m-grasptta-oc-bounded")} == {"contact_cvae_bounded"}
    assert extras["tables"]["table_contactcvae_rotation"]["rows"] == [
        "ours", "cc-gd", "cc-gd-bounded", "m-grasptta-ta", "m-grasptta-oc", "m-grasptta-oc-bounded"]


def test_a_grasp_diffuser_without_a_frame_trains_on_the_normalised_vector(repo):
    """The official units (m, rad) balance the loss only in a frame that centres the hand on its contact: a
    GraspDiffuser that reads the object with no frame (SceneDiffuser's) learnt no palm position in them (its
    hands 10 cm off the object, docs/baselines.md), so every default one with `frame: network` uses
    `diff_units: normalised`, and Ours' GraspDiffuser keeps the canonical frame with the official units."""
    default = _overlaid(repo)
    frameless = {name: c["network"]["diff_units"] for name, c in default["components"].items()
                 if c["kind"] == "grasp_diffuser" and c["network"]["frame"] == "network"}
    assert frameless == {"scene_diffuser": "normalised"}
    gd = default["components"]["grasp_diffuser"]["network"]
    assert (gd["frame"], gd["diff_units"]) == ("canonical", "official")


def test_the_smoke_run_covers_the_extras(repo):
    """The smoke config (.test/config/config.yaml) runs config/extras.yaml's diagnostics, so that CI exercises
    them: its palm SD methods, the gate's method and table, and Table 1's extra columns are the overlay's."""
    with open(repo / "config/extras.yaml") as fh:
        extras = yaml.safe_load(fh)
    with open(repo / ".test/config/config.yaml") as fh:
        smoke = yaml.safe_load(fh)
    assert smoke["evaluation"]["palm_sd"] == extras["evaluation"]["palm_sd"]
    assert smoke["evaluation"]["robust_sd"]["methods"]  # a cheap robust SD of its own
    assert smoke["methods"]["contactgen-gt"] == extras["methods"]["contactgen-gt"]
    assert smoke["tables"]["table_contactgen_gate"] == extras["tables"]["table_contactgen_gate"]
    assert smoke["tables"]["table1"]["columns"] == extras["tables"]["table1"]["columns"]


def test_the_upright_overlay_adds_an_upright_row_and_leaves_the_faithful_one_in_so3(repo):
    """config/upright.yaml over the default: `ours-upright`'s two components train about z only, with the
    faithful components' steps and batches, in frames that keep the object's orientation (a canonical frame
    would cancel it); `ours` and every built-in component keep the default SO(3) and canonical frames."""
    from tohgs.methods import method_components

    cfg = _overlaid(repo, "config/upright.yaml")
    comps, methods = cfg["components"], cfg["methods"]
    assert cfg["training"]["rotation"] == "so3"
    upright = method_components(methods["ours-upright"], comps)
    faithful = method_components(methods["ours"], comps)
    assert sorted(upright) == ["contact_diffuser_z", "grasp_diffuser_z"]
    for z, so3 in zip(sorted(upright), sorted(faithful)):
        assert comps[z]["kind"] == comps[so3]["kind"]
        assert {**comps[z]["network"], "frame": None} == {**comps[so3]["network"], "frame": None}
        assert comps[z]["network"]["frame"] in ("network", "contact") and comps[so3]["network"]["frame"] == "canonical"
        assert {**comps[z]["training"], "rotation": None} == {**comps[so3]["training"], "rotation": None}
        assert comps[z]["training"]["rotation"] == "z" and "rotation" not in comps[so3]["training"]
    assert cfg["tables"]["upright"]["rows"] == ["ours", "ours-upright", "ours-gt-contact"]


def test_the_adaptation_overlay_adds_m_grasptta_rows_without_their_adaptation(repo):
    """config/adaptation.yaml over the default: the two coarse rows are M-GraspTTA (TA) and (GT) with the
    adaptation's steps at 0 and everything else theirs (the same components, maps and sampling), and the
    adapted rows keep the default's adaptation."""
    cfg = _overlaid(repo, "config/adaptation.yaml")
    methods = cfg["methods"]
    for source in ("ta", "gt"):
        coarse, adapted = methods[f"m-grasptta-{source}-coarse"], methods[f"m-grasptta-{source}"]
        assert coarse["settings"] == {"tta": {"steps": 0}} and not adapted.get("settings")
        assert {k: v for k, v in coarse.items() if k not in ("label", "settings")} == \
            {k: v for k, v in adapted.items() if k not in ("label", "settings")}
    assert cfg["prediction"]["tta"]["steps"] > 0
    assert cfg["tables"]["adaptation"]["rows"][1::2] == ["m-grasptta-ta", "m-grasptta-gt"]


def test_the_viewers_default_labels_are_the_validated_defaults_without_the_validator():
    """The viewer's data module names the built-in methods from the schema file alone (it imports no
    tohgs.config), with the labels the validated default config has."""
    import ast
    import inspect

    import tohgs.viz.view_data as view_data

    labels = {name: block["label"] for name, block in validate_config({})["methods"].items()}
    assert view_data.default_labels() == labels
    imported = {n.module for n in ast.walk(ast.parse(inspect.getsource(view_data))) if isinstance(n, ast.ImportFrom)}
    assert "tohgs.config" not in imported
