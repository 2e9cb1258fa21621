"""Snakemake script of rule prior_figure: accepted and rejected prior grasps on several objects."""
from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.hand import HandAssets  # noqa: E402
from tohgs.viz.grasps import plot_prior_grasps  # noqa: E402

plot_prior_grasps(snakemake.input.stores, snakemake.params.objects_dir, HandAssets.load(snakemake.input.hand),
                  snakemake.output[0], snakemake.params.n_objects)
