"""Snakemake script of rule objects_figure: a grid of the selected objects and all bricks."""
from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.viz.objects import plot_objects  # noqa: E402

plot_objects(snakemake.input.catalog, snakemake.output[0], snakemake.params.max_objects, snakemake.params.seed)
