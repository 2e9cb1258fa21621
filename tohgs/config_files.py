"""Reading config files strictly: what a plain YAML load lets through silently.

A YAML mapping that repeats a key keeps the last value without a word (``qr: {max_sd: 0.05}`` followed by
another ``qr:`` block puts ``max_sd`` back to its default), and aliases of aliases ("billion laughs") build a
small graph that anything walking it as a tree expands exponentially. :func:`read_config_file` composes the
file's node graph (cheap: an alias is a reference to its anchor's node), counts the values it stands for with
each alias counted as often as it is used, without expanding anything, refuses more than
:data:`tohgs.config.MAX_CONFIG_VALUES` and refuses a repeated key, naming the file, the line and the key.

Snakemake reads ``--configfile`` files itself and merges them into one mapping before the workflow's code
runs; its merge copies every mapping it reaches through an alias into a new one, so a billion laughs of nested
mappings hangs Snakemake before any check of ours. Check a file you did not write first:
``python -m tohgs.config_files FILE...`` (``make reproduce CONFIG=FILE`` does). The workflow reads every
config file again with these rules when it parses (``workflow/rules/common.smk``), which catches repeated
keys and laughs small enough for Snakemake's merge to finish.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import yaml


class ConfigFileError(ValueError):
    """A config file that cannot be read as it is written; the message names the file and the line."""


class _Loader(yaml.SafeLoader):
    """PyYAML's safe loader (no Python objects) that refuses a key repeated in one mapping."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: dict[Any, yaml.Node] = {}
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue  # ``<<: *anchor`` merges on purpose; the explicit keys override it
            key = self.construct_object(key_node, deep=True)
            try:
                first = seen.get(key)
            except TypeError:  # an unhashable key: the base class reports it
                break
            if first is not None:
                raise ConfigFileError(
                    f"{self.name}: line {key_node.start_mark.line + 1}: key {key!r} repeats the key of line "
                    f"{first.start_mark.line + 1} in the same mapping (YAML keeps only the last one, silently); "
                    "merge the two blocks")
            seen[key] = key_node
        return super().construct_mapping(node, deep=deep)


def _count_values(root: yaml.Node, limit: int, name: str) -> int:
    """The nodes ``root`` stands for (mappings, sequences, scalars, a mapping's keys too), each alias
    counted as often as it is used; refuses more than ``limit`` or a node that contains itself. Linear in the
    node graph: each node's count is computed once."""
    counts: dict[int, int] = {}
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    open_nodes: set[int] = set()
    while stack:
        node, done = stack.pop()
        nid = id(node)
        if nid in counts:
            continue
        children = ([n for kv in node.value for n in kv] if isinstance(node, yaml.MappingNode)
                    else list(node.value) if isinstance(node, yaml.SequenceNode) else [])
        if not done:
            if nid in open_nodes:
                raise ConfigFileError(f"{name}: line {node.start_mark.line + 1}: an alias refers to a node that "
                                      "contains it (a recursive structure); not a configuration")
            open_nodes.add(nid)
            stack.append((node, True))
            stack += [(c, False) for c in children if id(c) not in counts]
            continue
        open_nodes.discard(nid)
        total = 1 + sum(counts[id(c)] for c in children)
        if total > limit:
            raise ConfigFileError(
                f"{name}: line {node.start_mark.line + 1}: the block here stands for more than {limit} values "
                "once its aliases are expanded (aliases of aliases: a 'billion laughs'); refused unexpanded")
        counts[nid] = total
    return counts[id(root)]


def _json_mapping(pairs: list[tuple[str, Any]], path: Path) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise ConfigFileError(f"{path}: key {key!r} repeats in one object (JSON keeps only the last one, "
                                  "silently); merge the two")
        out[key] = value
    return out


def read_config_file(path: str | Path, limit: int | None = None) -> dict[str, Any]:
    """A config file (YAML or JSON), read strictly: no repeated key in a mapping, at most ``limit`` values
    with aliases expanded (counted without expanding), a mapping at the top level.

    Args:
        path: the file.
        limit: most values; default :data:`tohgs.config.MAX_CONFIG_VALUES`.

    Raises:
        ConfigFileError: any of the above, or a file that is not YAML; the message names the file.
    """
    if limit is None:
        from tohgs.config import MAX_CONFIG_VALUES

        limit = MAX_CONFIG_VALUES
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigFileError(f"{path}: cannot be read ({exc})") from exc
    if text.lstrip().startswith("{"):  # JSON, as Snakemake tries first (no aliases; repeated keys refused)
        try:
            data = json.loads(text, object_pairs_hook=lambda pairs: _json_mapping(pairs, path))
        except json.JSONDecodeError:
            pass  # YAML's flow style also starts with "{"
        else:
            if not isinstance(data, dict):
                raise ConfigFileError(f"{path}: expected a mapping at the top level, got {type(data).__name__}")
            return data
    try:
        loader = _Loader(text)
        loader.name = str(path)
        try:
            node = loader.get_single_node()
            if node is None:
                return {}
            _count_values(node, limit, str(path))
            data = loader.construct_document(node)
        finally:
            loader.dispose()
    except yaml.YAMLError as exc:
        raise ConfigFileError(f"{path}: not valid YAML ({exc})") from exc
    if not isinstance(data, dict):
        raise ConfigFileError(f"{path}: expected a mapping at the top level, got {type(data).__name__}")
    return data


def check_config_files(paths: Iterable[str | Path]) -> None:
    """:func:`read_config_file` each of ``paths`` (the workflow's config files); raises its error."""
    for p in paths:
        read_config_file(p)


def main(argv: list[str] | None = None) -> int:
    """``python -m tohgs.config_files FILE...``: read each file strictly, then validate the embedded default with
    the files merged over it in order (as ``snakemake --configfile FILE...`` would); exit 1 with the first problem."""
    from tohgs.config import ConfigError, validate_config
    from tohgs.settings import merge

    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] in ("-h", "--help"):
        print("usage: python -m tohgs.config_files FILE... (check config files before snakemake --configfile)")
        return 0 if argv else 2
    from tohgs.config import REPO_ROOT

    try:
        cfg = read_config_file(REPO_ROOT / "config" / "config.yaml")
        for p in argv:
            merge(cfg, read_config_file(p))
        validate_config(cfg)
    except (ConfigFileError, ConfigError) as exc:
        print(f"invalid configuration: {exc}", file=sys.stderr)
        return 1
    print(f"ok: {', '.join(argv)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
