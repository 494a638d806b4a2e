"""The one command-line entry point, ``hdphm``.

Each package contributes its sub-commands through a module with a
``register(subparsers)`` function; this file only lists those modules, so a
newcomer finds a command's code by its package. Registration must stay cheap:
heavy imports (torch, rclpy, onnxruntime) belong inside the handlers.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import os
import sys

#: Exceptions that mean bad input, not a bug: reported as one line, exit status 1.
#: (``hd_bag.BagError`` is a ValueError; numpy/scipy refuse bad arrays with ValueError.)
#: FloatingPointError: a simulation or training that diverged (the messages say where and what to change)
USER_ERRORS = (ValueError, FileNotFoundError, NotADirectoryError, IsADirectoryError, PermissionError,
               FloatingPointError)

#: Modules that add sub-commands, in the order ``hdphm --help`` shows them.
COMMAND_MODULES = (
    "hdphm.demo_cli",        # demo: the README's main job
    "hd_sim.cli",            # sim fleet | sim mission | sim effects
    "hd_bag.cli",            # validate, import-csv, inspect
    "hd_twin.cli",           # train, tune, twin eval|export|show
    "hd_prognostic.cli",     # prognose, metrics, prognostic eval
    "hd_ground.cli",         # discover, ground ...
    "hdphm.ros_cli",         # node, stack, replay, record
    "hdphm.bench_cli",       # bench
    "hdphm.report_cli",      # report: one self-contained HTML page of a run or fleet store
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hdphm",
        description="Harmonic-drive PHM stack: simulate, train the twin, monitor, prognose, discover.",
    )
    from hdphm import __version__

    parser.add_argument("--version", action="version", version=f"hdphm {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        # A package whose command module is not written yet is simply absent;
        # an import error inside an existing module is a real error and raises.
        if importlib.util.find_spec(name) is None:
            continue
        importlib.import_module(name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        rc = args.func(args)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except USER_ERRORS as e:
        # Bad input (a bag that breaks the contract, a missing file, an absurd value): the messages
        # of these errors name the file and the problem; a traceback would only hide them.
        # HDPHM_DEBUG=1 re-raises for the traceback.
        if os.environ.get("HDPHM_DEBUG"):
            raise
        print(f"hdphm {args.command}: error: {e}", file=sys.stderr)
        return 1
    rc = int(rc or 0)
    if argv is None and getattr(args, "fast_exit", False):
        # a ROS process command that has closed its files and shut rclpy down: skip the interpreter's
        # teardown (measured ~2 s of middleware destructors on the 2-core machine), so SIGTERM/Ctrl-C
        # stop it within the 2 s a supervisor allows. Only for the real command line (argv from sys).
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(rc)
    return rc


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
