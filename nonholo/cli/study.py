"""``nonholo study [NAME …]``: run the registered studies and write a report folder."""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from nonholo.cli import (EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_OK, collector_for_long_work, processes_count,
                         signals_interrupt)


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
    parser.add_argument("--quiet", action="store_true",
                        help="no progress (bar on a terminal, one-line logs on stderr otherwise) and no tables")
    parser.add_argument("--sampling", choices=("uniform", "solver-steps", "both"), default="both",
                        help="statistics over the uniform grid, the solver's accepted steps, or both (default)")
    parser.add_argument("--processes", type=processes_count, default=2, metavar="N",
                        help="work beside the study in up to N processes forked from this one: the report's "
                             "figures drawn while the next study runs, the leader's gain sweeps while its tests run; "
                             "with N > 0, one more compiles the later studies ahead at low priority "
                             "(default: %(default)s; 0: everything in this process, in order)")
    parser.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from nonholo.errors import NonholoInputError
    from nonholo.studies import StudyOptions
    from nonholo.studies.report import chosen_studies

    outcomes = []   # (name, wall time, ok) of each study: its result goes once its section is written
    try:
        options = StudyOptions(Path(args.out), quick=args.quick, progress=not args.quiet, sampling=args.sampling,
                               processes=args.processes)
        chosen_studies(args.names)  # unknown names fail before any work
        import nonholo.studies.plots  # noqa: F401  (matplotlib: imported before the collector is tuned)
        with collector_for_long_work(), signals_interrupt():   # SIGTERM, SIGHUP: helpers reaped, as on Ctrl-C
            page, report_s = _run_studies(args, options, outcomes)
    except NonholoInputError as exc:
        print(f"nonholo study: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except (RuntimeError, OSError) as exc:
        print(f"nonholo study: failed: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    if args.quiet:
        print(f"report: {page}")
    else:
        print(f"report: {page} (figures and data files: {report_s:.1f} s beyond the studies)")
        print(f"wall time: {command_wall_time():.1f} s in all; studies "
              + ", ".join(f"{name} {elapsed:.1f} s" for name, elapsed, _ in outcomes) + f", report {report_s:.1f} s")
    return EXIT_OK if all(ok for _, _, ok in outcomes) else EXIT_FAILURE


def _run_studies(args, options, outcomes: list) -> tuple[Path, float]:
    """Run the chosen studies, each one's report section written as soon as it finishes;
    returns the page and the seconds spent on the report."""
    from nonholo.studies.report import ReportWriter, each_result

    report_s = 0.0
    with ReportWriter(options.out_dir, options) as writer:
        for result in each_result(args.names, options):
            if not args.quiet:   # a study's summary as soon as it finishes
                print(result.text())
                print(f"\nstudy {result.name}: {result.elapsed_s:.1f} s (simulations and statistics, wall time)\n",
                      flush=True)
            report_s += writer.add(result)
            outcomes.append((result.name, result.elapsed_s, result.ok))
            del result   # its section is written, its figures drawing: the next study runs without its arrays
        started = time.perf_counter()
        page = writer.finish()
    return page, report_s + time.perf_counter() - started


_STARTED = time.perf_counter()


def command_wall_time() -> float:
    """Seconds since this process started (Linux: from /proc; elsewhere since this module
    was imported, i.e. after Python's start-up)."""
    try:
        with open("/proc/self/stat") as handle:
            start_ticks = int(handle.read().rsplit(")", 1)[1].split()[19])
        with open("/proc/uptime") as handle:
            uptime = float(handle.read().split()[0])
        return uptime - start_ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError, AttributeError):
        return time.perf_counter() - _STARTED
