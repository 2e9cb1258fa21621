"""Snakemake script of rule scenes: the configurations of one task and target object."""
from pathlib import Path

from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.sim.scenes import make_scene_store  # noqa: E402

make_scene_store(snakemake.wildcards.task, snakemake.wildcards.object, snakemake.params.pool, Path(snakemake.input.supports).parent,
                 f"{snakemake.input.supports}/supports.json", snakemake.params.settings, snakemake.params.seed,
                 snakemake.output[0])
