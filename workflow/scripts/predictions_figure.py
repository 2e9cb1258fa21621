"""Snakemake script of rule predictions_figure: predicted hands in their initial and goal scenes."""
from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.hand import HandAssets  # noqa: E402
from tohgs.viz.predictions import plot_predictions  # noqa: E402

inp = snakemake.input
plot_predictions(list(inp.predictions), inp.scenes, snakemake.params.objects_dir, f"{inp.supports}/supports.json",
                 HandAssets.load(inp.hand), snakemake.output[0], snakemake.params.configs, snakemake.params.labels)
