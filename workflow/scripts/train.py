"""Snakemake script of rule train: one component for one task."""
from pathlib import Path

from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.hand import HandAssets, HandModel  # noqa: E402
from tohgs.models.train import train_component  # noqa: E402

inp, out, p = snakemake.input, snakemake.output, snakemake.params
train_component(Path(out.model).stem, p.kind, snakemake.wildcards.task, inp.shards, p.network,
                {**p.settings, "threads": snakemake.threads}, out.model, hand=HandModel(HandAssets.load(inp.hand)),
                curve_png=out.curve)
