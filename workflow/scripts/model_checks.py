"""Snakemake script of rule model_checks: the checks each trained component's kind declares (do a task's
diffusers use their condition, do they fit their training data)."""
from pathlib import Path

from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.hand import HandAssets, HandModel  # noqa: E402
from tohgs.models.checks import model_checks  # noqa: E402

inp = snakemake.input
model_checks(snakemake.wildcards.task, inp.shards, {Path(m).stem: m for m in inp.models},
             HandModel(HandAssets.load(inp.hand)), snakemake.output[0], snakemake.params.checks,
             seed=snakemake.params.seed)
