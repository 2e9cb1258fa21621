"""Snakemake script of rule train: one diffuser for one task."""
from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.hand import HandAssets, HandModel  # noqa: E402
from tohgs.models.train import train_model  # noqa: E402

w, p = snakemake.wildcards, snakemake.params
train_model(w.model, w.task, snakemake.input.shards, p.model, {**p.settings, "threads": snakemake.threads},
            snakemake.output.model, hand=HandModel(HandAssets.load(snakemake.input.hand)), curve_png=snakemake.output.curve)
