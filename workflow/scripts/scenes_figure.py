"""Snakemake script of rule scenes_figure: initial and goal scenes side by side for one task."""
from pathlib import Path

from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.viz.scenes import plot_scenes  # noqa: E402

plot_scenes(snakemake.input.scenes, snakemake.params.objects_dir, Path(snakemake.input.supports) / "supports.json",
            snakemake.output[0], snakemake.wildcards.task, snakemake.params.max_configs)
