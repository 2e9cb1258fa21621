"""The ``tohgs`` command: one entry point for the library's command lines (``tohgs --help``).

Each subcommand is the ``main(argv)`` of a module that also runs as ``python -m <module>`` (kept as an alias):

=================  =====================  ==============================================================
subcommand         module                 what it does
=================  =====================  ==============================================================
``grasp``          tohgs.own_object       grasps for your own mesh with a finished run's trained models
``export``         tohgs.export           a prediction store's grasps as hand meshes or MANO parameters
``view``           tohgs.viz.view         the 3D viewer of a finished run (or its static HTML export)
``check-config``   tohgs.config_files     config files read strictly and validated, before Snakemake
``official``       tohgs.official         the official TOHGS dataset: import, export
=================  =====================  ==============================================================
"""

from __future__ import annotations

import importlib
import sys

#: subcommand -> (module with ``main(argv)``, one line of help)
COMMANDS = {
    "grasp": ("tohgs.own_object", "grasps for your own mesh (.obj, .stl, .ply) with a finished run's trained models"),
    "export": ("tohgs.export", "a prediction store's grasps as hand meshes (OBJ, PLY, GLB) or MANO parameters (NPZ)"),
    "view": ("tohgs.viz.view", "the 3D viewer of a finished run's results, or its static HTML export"),
    "check-config": ("tohgs.config_files", "check config files before snakemake --configfile"),
    "official": ("tohgs.official.__main__", "the official TOHGS dataset: import it, export predictions to it"),
}


def _usage() -> str:
    width = max(map(len, COMMANDS))
    lines = [f"  {name:<{width}}  {text}" for name, (_, text) in COMMANDS.items()]
    return "usage: tohgs COMMAND [ARGS...]   (tohgs COMMAND --help for its arguments)\n\ncommands:\n" + "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Dispatch ``tohgs COMMAND ARGS...`` to the command's module; ``tohgs --help`` lists them."""
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] in ("-h", "--help", "help"):
        print(_usage())
        return 0 if argv else 2
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        print(f"tohgs: unknown command {name!r}\n\n{_usage()}", file=sys.stderr)
        return 2
    module = importlib.import_module(COMMANDS[name][0])
    return int(module.main(rest) or 0)


if __name__ == "__main__":
    sys.exit(main())
