"""Snakemake script of rule table: one table of the config (csv, markdown) and its QR threshold grid."""
import logging

from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.io import atomic_path  # noqa: E402
from tohgs.metrics.bootstrap import BootstrapSettings  # noqa: E402
from tohgs.metrics.tables import QualityThresholds, markdown, metric_table, qr_grid, read_metrics  # noqa: E402

p, out = snakemake.params, snakemake.output
rows = read_metrics(snakemake.input.metrics, p.replicas)
pending = {row["label"]: row["reason"] for row in p.pending}
table = metric_table(rows, p.tasks, p.rows, p.labels, p.columns, QualityThresholds(**p.qr), list(pending),
                     BootstrapSettings(**p.bootstrap), p.paper)
grid = qr_grid(rows, p.tasks, p.rows, p.labels, p.qr_grid["max_pv"], p.qr_grid["max_sd"])
with atomic_path(out.csv) as tmp:
    table.to_csv(tmp, index=False, float_format="%.6g")
with atomic_path(out.md) as tmp, open(tmp, "w") as fh:
    fh.write(markdown(table, notes=pending))
with atomic_path(out.grid) as tmp:
    grid.to_csv(tmp, index=False, float_format="%.6g")
logging.getLogger("table").info("%s\n%s", out.csv, markdown(table, notes=pending))
