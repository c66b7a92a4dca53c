"""The `srlab` command line: one module a command, or a family of small ones.

`simulate`, `experiment`, `sweep`, `phase`, `teachers`, `equal-start`, `noise`,
`export`, `outside` (list, check, experiment) and `study` (its actions: create, add,
status, forget, export) have a module each; `tune` holds `tune` and `qlambda-sweep`,
`world` holds `probe`, `world-check` and `world` (list, check, show), `run` holds `run`
and `runs`, `db` and `serve` the database and the service. `common` has what they share:
argument types and groups, the backend choice, progress bars and tables. Each module adds
its parsers with a `handler`, and imports what only its handler needs (storage, the
service, the report writers) when it runs, so that a command starts without the others'
dependencies.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from core.errors import CoreError
from server.backends import BackendError
from server.cli import (
    db,
    equal_start,
    experiment,
    export,
    noise,
    outside,
    phase,
    run,
    serve,
    simulate,
    study,
    sweep,
    teachers,
    tune,
    world,
)
from server.cli.common import Handler, UsageError


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every `srlab` command."""
    parser = argparse.ArgumentParser(
        prog="srlab",
        description="A behaviour-based control and learning architecture with knowledge "
        "propagation (Suh et al.), on a simulated AmigoBot.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    # In the order `srlab --help` lists them.
    simulate.add_parser(sub)
    experiment.add_parser(sub)
    sweep.add_parser(sub)
    phase.add_parser(sub)
    tune.add_tune_parser(sub)
    world.add_probe_parser(sub)
    world.add_world_check_parser(sub)
    world.add_world_parser(sub)
    teachers.add_parser(sub)
    equal_start.add_parser(sub)
    noise.add_parser(sub)
    tune.add_qlambda_sweep_parser(sub)
    outside.add_parser(sub)
    db.add_parser(sub)
    run.add_run_parser(sub)
    serve.add_parser(sub)
    run.add_runs_parser(sub)
    export.add_parser(sub)
    study.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `srlab` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    args.argv = list(argv) if argv is not None else sys.argv[1:]
    handler: Handler = args.handler
    try:
        return handler(args, sys.stdout, sys.stderr)
    except UsageError as e:
        parser.error(str(e))
    except (CoreError, ValueError, OSError, BackendError) as e:
        parser.exit(2, f"srlab: error: {e}\n")
    except KeyboardInterrupt:
        parser.exit(130, "srlab: interrupted\n")
    except Exception as e:
        # Anything else is a bug or an adapter's error (a database driver's, say): one line
        # for the person at the shell, and the traceback only when asked for.
        if os.environ.get("SRLAB_DEBUG"):
            raise
        first = (str(e).strip().splitlines() or [""])[0]
        parser.exit(
            1, f"srlab: error: {type(e).__name__}: {first} (SRLAB_DEBUG=1 shows the traceback)\n"
        )


__all__ = ["build_parser", "main"]
