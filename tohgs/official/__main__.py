"""``python -m tohgs.official``: the command line of the official dataset's importer and exporter."""

from __future__ import annotations

import argparse
import logging

import tohgs.official
from tohgs.assets.mesh import MeshLimits
from tohgs.official.exporter import export_official
from tohgs.official.format import TASKS
from tohgs.official.importer import import_official


def main(argv: list[str] | None = None) -> int:
    """``python -m tohgs.official import ROOT OUT`` / ``export PREDICTIONS SCENES_DIR RUN_DIR``."""
    from tohgs.hand import load_hand_assets

    parser = argparse.ArgumentParser(prog="python -m tohgs.official", description=tohgs.official.__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    imp = sub.add_parser("import", help="official tree -> tohgs stores")
    imp.add_argument("root")
    imp.add_argument("out")
    imp.add_argument("--tasks", nargs="+", default=list(TASKS), choices=TASKS)
    imp.add_argument("--density", type=float, default=500.0)
    imp.add_argument("--cache-dir", default=None)
    imp.add_argument("--max-faces", type=int, default=MeshLimits.max_faces,
                     help="largest mesh to parse, faces (objects.limits.max_faces)")
    imp.add_argument("--max-file-mb", type=float, default=MeshLimits.max_file_mb,
                     help="largest mesh file to parse, MB (objects.limits.max_file_mb)")
    exp = sub.add_parser("export", help="tohgs prediction store -> official result/<run>/<obj>.npy")
    exp.add_argument("predictions")
    exp.add_argument("scenes_dir")
    exp.add_argument("run_dir")
    for p in (imp, exp):
        p.add_argument("--hand", default="anny", choices=("anny", "mano"))
        p.add_argument("--mano-path", default=None)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(message)s")
    hand = load_hand_assets(args.hand, args.mano_path)
    if args.command == "import":
        report = import_official(args.root, args.out, hand, args.tasks, args.density, cache_dir=args.cache_dir,
                                 limits=MeshLimits(args.max_faces, args.max_file_mb))
        for p in report.problems:
            print(f"{p['kind']}: {p['path']}: {p['reason']}")
        print(f"{report.files_read} files read, {report.n_problems} problems; {report.tasks}")
        return 1 if report.n_problems else 0
    for stem, path in export_official(args.predictions, args.scenes_dir, hand, args.run_dir).items():
        print(f"{stem}: {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

