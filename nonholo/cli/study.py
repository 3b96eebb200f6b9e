"""``nonholo study [NAME …]``: run the registered studies and write a report folder."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from nonholo.cli import EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_OK


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "study", help="reproduce the thesis's studies and write a report (index.html, CSV, JSON)",
        description="Run studies (default: all) and write DIR/index.html with figures, tables and the "
                    "differences from the thesis, plus CSV and JSON of every number. The leader study reproduces "
                    "thesis Chapter 5 (Tables 5.2-5.6).",
        epilog="Uniform-grid statistics are always computed; --sampling uniform skips the variable-step solver. "
               "Exit codes: 0 ok, 1 failure, 2 bad input.")
    parser.add_argument("names", nargs="*", metavar="STUDY", help="studies to run (default: all)")
    parser.add_argument("--out", metavar="DIR", default="study-report", help="report folder (default: %(default)s)")
    parser.add_argument("--quick", action="store_true", help="coarser grids and shorter sweeps (a smoke test)")
    parser.add_argument("--quiet", action="store_true", help="no progress bars and no tables on stdout")
    parser.add_argument("--sampling", choices=("uniform", "solver-steps", "both"), default="both",
                        help="statistics over the uniform grid, the solver's accepted steps, or both (default)")
    parser.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from nonholo.errors import NonholoInputError
    from nonholo.studies import StudyOptions, run_studies

    try:
        options = StudyOptions(Path(args.out), quick=args.quick, progress=not args.quiet and sys.stderr.isatty(),
                               sampling=args.sampling)
        results, page = run_studies(args.names, options)
    except NonholoInputError as exc:
        print(f"nonholo study: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except (RuntimeError, OSError) as exc:
        print(f"nonholo study: failed: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    if not args.quiet:
        for result in results:
            print(result.text())
            print()
    print(f"report: {page}" + ("" if args.quiet else f" ({sum(r.elapsed_s for r in results):.1f} s)"))
    return EXIT_OK if all(r.ok for r in results) else EXIT_FAILURE
