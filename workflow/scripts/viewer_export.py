"""Snakemake script of rule viewer: one task's static 3D viewer (a self-contained HTML file)."""
from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.metrics.tables import QualityThresholds  # noqa: E402
from tohgs.viz.view import export_html  # noqa: E402
from tohgs.viz.view_data import TaskResults  # noqa: E402

inp, p = snakemake.input, snakemake.params
data = TaskResults(snakemake.wildcards.task, list(inp.predictions), list(inp.shards), list(inp.scenes),
                   p.objects_dir, f"{inp.supports}/supports.json", inp.hand, list(inp.metrics), dict(p.labels),
                   QualityThresholds(**p.qr))
export_html(data, snakemake.output[0], p.configs, p.samples, methods=list(p.labels))
