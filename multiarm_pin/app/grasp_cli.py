"""Command line of the grasp analysis: ``multiarm-pin grasp FILE.yaml`` (or this module).

The subcommand's ``configure_parser`` and ``run``, which :mod:`multiarm_pin.app.cli` wires
into the one command line (as ``study/cli.py`` and ``design/cli.py`` hold theirs). It sits in
the application shell, not in ``grasp/``, because it reads scenario files
(:mod:`multiarm_pin.app.grasp_input`); the analysis is :mod:`multiarm_pin.grasp`'s.

FILE is a grasp file or a scenario file (its fingertip contacts, read as a study in mode
``grasp`` reads them: :mod:`multiarm_pin.app.grasp_input`). ``configure_parser`` adds the
arguments to a parser given by the main command line and ``run`` executes them;
``python -m multiarm_pin.app.grasp_cli FILE`` runs them stand-alone.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from multiarm_pin.exceptions import MultiArmError, ScenarioError
from multiarm_pin.grasp.report import analyse, draw_grasp, format_report


def configure_parser(parser: argparse.ArgumentParser) -> None:
    """Add the grasp command's arguments (FILE, --json, --seventh, --picture, --no-picture)."""
    parser.add_argument("file", metavar="FILE",
                        help="grasp YAML file, or a scenario file (its fingertip contacts)")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    parser.add_argument(
        "--seventh",
        metavar="K",
        type=int,
        default=None,
        help="compute the seventh-contact region of contact K only (numbered from 1 in the "
             "file's order; default: every contact whose removal leaves six independent ones)",
    )
    parser.add_argument(
        "--picture",
        metavar="PATH",
        default=None,
        help="where to save the picture (default: <stem>_grasp.png next to FILE, or in the "
             "current folder for a file shipped with the package)",
    )
    parser.add_argument("--no-picture", action="store_true", help="do not draw the picture")


def picture_formats() -> list[str]:
    """File extensions (without the dot) that matplotlib can save a picture as, sorted."""
    from matplotlib.backend_bases import FigureCanvasBase

    return sorted(FigureCanvasBase.get_supported_filetypes())


def _default_picture(file: Path) -> Path:
    """``<stem>_grasp.png`` beside ``file``, or in the current folder for a shipped file."""
    from multiarm_pin.data import data_path

    name = f"{file.stem}_grasp.png"
    if file.resolve().is_relative_to(data_path().resolve()):
        return Path(name)  # never write into the installed package
    return file.with_name(name)


def run(args: argparse.Namespace) -> int:
    """Analyse ``args.file`` and print the report.

    Returns:
        0 on success; 2 when the file or the grasp is invalid (message on stderr naming the
        file and the key).
    """
    picture = None
    if not getattr(args, "no_picture", False) and args.picture:
        picture = Path(args.picture)
        formats = picture_formats()
        fmt = picture.suffix.lstrip(".").lower()
        if fmt not in formats:
            print(f"error: --picture {picture}: unsupported picture format "
                  f"{fmt or '(no extension)'!r}; expected a file name ending in one of "
                  f"{', '.join('.' + f for f in formats)}", file=sys.stderr)
            return 2
    from multiarm_pin.app.grasp_input import load_grasp_input

    try:
        source = load_grasp_input(args.file)
        gf = source.grasp_file
        seventh = getattr(args, "seventh", None)
        if seventh is not None and not 1 <= seventh <= len(gf.grasp):
            print(f"error: --seventh {seventh}: expected a contact number in "
                  f"1..{len(gf.grasp)} ({gf.path} has {len(gf.grasp)} contacts, numbered from "
                  "1 in the order of the file)", file=sys.stderr)
            return 2
        rep, region = analyse(gf, None if seventh is None else seventh - 1)
        rep["kind"] = source.kind
        rep["contact_names"] = list(source.contact_names)
        rep["notes"] = list(source.notes) + rep["notes"]
    except ScenarioError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except MultiArmError as exc:
        print(f"error: {args.file}: {exc}", file=sys.stderr)
        return 2
    if not getattr(args, "no_picture", False):
        path = picture or _default_picture(gf.path)
        try:
            draw_grasp(gf.grasp, region, path, title=gf.path.name)
            rep["picture"] = str(path)
        except (OSError, ValueError) as exc:
            print(f"error: cannot write the picture {path}: {exc}", file=sys.stderr)
            return 2
    if args.json:
        print(json.dumps(rep, indent=2))
    else:
        print(format_report(rep))
    return 0


def main(argv: list[str] | None = None) -> int:
    """Stand-alone entry point (``python -m multiarm_pin.app.grasp_cli``)."""
    parser = argparse.ArgumentParser(prog="multiarm-pin grasp", description=__doc__)
    configure_parser(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
