"""Snakemake script of rule claims: the paper's claims checked on this run (csv, markdown)."""
import logging

from tohgs.io import setup_logging

setup_logging(snakemake.log[0])

from tohgs.io import atomic_path  # noqa: E402
from tohgs.metrics.bootstrap import BootstrapSettings  # noqa: E402
from tohgs.metrics.claims import claims_markdown, claims_table  # noqa: E402
from tohgs.metrics.tables import QualityThresholds, read_metrics  # noqa: E402

p, out = snakemake.params, snakemake.output
boot = BootstrapSettings(**p.bootstrap)
rows = read_metrics(snakemake.input.metrics, p.replicas)
table = claims_table(rows, p.claims, p.tables, p.labels, QualityThresholds(**p.qr),
                     boot, list(p.tasks))
with atomic_path(out.csv) as tmp:
    table.to_csv(tmp, index=False, float_format="%.6g")
with atomic_path(out.md) as tmp, open(tmp, "w") as fh:
    fh.write(claims_markdown(table, boot.level))
logging.getLogger("claims").info("%s\n%s", out.csv, claims_markdown(table, boot.level))
