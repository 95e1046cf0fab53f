"""The `gngdt` command line: one subcommand per service or job.

Each subcommand lives in its own module exposing ``add_arguments(parser)`` and
``main(args) -> int``.
Modules keep heavy imports (zenoh, rerun, numba) inside ``main`` so that ``--help`` stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
from typing import NoReturn

#: subcommand -> (module, one-line help). Order is the order shown by ``gngdt --help``.
SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "run": ("gngdt.services.run", "run capture, learner and logger on one recording (loopback)"),
    "capture": ("gngdt.services.capture", "replay a recording as a camera on zenoh"),
    "learn": ("gngdt.services.learner", "learn GNG-DT topologies from a camera's point clouds"),
    "log": ("gngdt.services.logger", "log every gngdt stream to rerun"),
    "router": ("gngdt.services.router", "run a zenoh router for standalone services"),
    "record": ("gngdt.services.record", "make recordings: synthetic scenes or real RGB-D frames"),
    "segment": ("gngdt.services.segment", "segment RGB-D frames: a label image per frame"),
    "ros2": ("gngdt.services.ros2", "bridge to ROS 2 (rmw_zenoh): camera topics in, results out"),
    "eval": ("gngdt.eval.cli", "evaluate: the paper's tables, recordings, logged runs"),
}

EPILOG = """examples:
  gngdt run recordings/tabletop.mcap                 # whole pipeline, writes runs/*.rrd
  gngdt record synth --scene tabletop --frames 30 --out my.mcap
  gngdt router & gngdt capture my.mcap --loop & gngdt learn & gngdt log --save out.rrd
  gngdt segment recordings/tabletop.mcap --out seg/tabletop
  gngdt eval paper --trials 5 --out report/
"""


def first_paragraph(text: str) -> str:
    """The first paragraph of a docstring, on one line (a subcommand's description)."""
    return " ".join(text.strip().split("\n\n")[0].split())


def add_common_arguments(parser: argparse.ArgumentParser) -> None:
    """Options every subcommand accepts, and ``args.environment`` (`main` sets the one read
    from the process's environment; parsed alone, an empty one)."""
    from gngdt.services.plumbing.environment import Environment

    parser.add_argument(
        "--log-level",
        default="INFO",
        choices=["DEBUG", "INFO", "WARNING", "ERROR"],
        help="logging verbosity (default: INFO)",
    )
    parser.set_defaults(environment=Environment())


def gngdt_version() -> str:
    """The installed gngdt's version (its package metadata)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("gngdt")
    except PackageNotFoundError:  # run from a checkout that was never installed
        return "unknown (not installed)"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="gngdt",
        description="Online, unsupervised 3D perception: GNG-DT over zenoh.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"gngdt {gngdt_version()}")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (module_name, help_text) in SUBCOMMANDS.items():
        module = importlib.import_module(module_name)
        sub = subparsers.add_parser(
            name,
            help=help_text,
            description=first_paragraph(module.__doc__ or help_text),
            epilog=getattr(module, "EXAMPLES", None),
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        module.add_arguments(sub)
        for leaf in leaf_parsers(sub):
            add_common_arguments(leaf)
            leaf.set_defaults(_parser=leaf)  # whose usage an unknown option prints
        sub.set_defaults(_module=module)
    return parser


def parse_arguments(parser: argparse.ArgumentParser, argv: list[str] | None) -> argparse.Namespace:
    """``parser``'s arguments; an option no parser knows is refused by the subcommand that
    was given it, with that subcommand's usage (argparse's own refusal prints the top-level
    usage, which does not list the subcommand's options): exit 2."""
    args, unknown = parser.parse_known_args(argv)
    if unknown:
        getattr(args, "_parser", parser).error(f"unrecognized arguments: {' '.join(unknown)}")
    return args


def leaf_parsers(parser: argparse.ArgumentParser) -> list[argparse.ArgumentParser]:
    """The parsers that take options: ``parser`` itself, or those of its sub-subcommands."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return [leaf for sub in dict.fromkeys(action.choices.values())
                    for leaf in leaf_parsers(sub)]
    return [parser]


def main(argv: list[str] | None = None) -> int:
    from gngdt.services.plumbing import lifecycle
    from gngdt.services.plumbing.environment import read_environment

    # One try from the handlers' installation on: a stop signal raises KeyboardInterrupt
    # wherever start-up stands (inside install() once its first handler is set, or while logging
    # is configured), and one escaping main() made Python kill itself with SIGINT (exit -2).
    try:
        # first: a signal during the imports below must stop us too (reading the environment
        # imports nothing)
        environment = read_environment()
        lifecycle.install(environment.parent_pid)
        from gngdt.schemas.images import MAX_IMAGE_PIXELS

        # before OpenCV loads: the largest image it may decode, rather than its own 2**30
        # pixels (3 GB for a few kilobytes of PNG)
        os.environ.setdefault("OPENCV_IO_MAX_IMAGE_PIXELS", str(MAX_IMAGE_PIXELS))
        args = parse_arguments(build_parser(), argv)
        logging.basicConfig(
            level=getattr(logging, args.log_level),
            format="%(asctime)s %(levelname)s %(name)s: %(message)s",
        )
        for problem in environment.problems:
            logging.getLogger(__name__).warning("%s", problem)
        args.environment = environment
        from gngdt.services.plumbing.session import ZenohSetupError
        from gngdt.services.plumbing.settings import apply_settings

        try:  # a service started by `gngdt run` reads its options from the run's file
            apply_settings(args, getattr(args._module, "SETTINGS", []))
        except ValueError as error:
            logging.getLogger(__name__).error("%s", error)
            return 2
        try:
            return int(args._module.main(args) or 0)
        except ZenohSetupError as error:  # a wrong zenoh configuration, no router: said, exit 1
            logging.getLogger(__name__).error("%s", error)
            return 1
    except KeyboardInterrupt:
        return 130


def command() -> NoReturn:
    """The `gngdt` executable: :func:`main`, then an exit that no leftover thread holds up (a
    crash too: its traceback is logged, exit 1)."""
    from gngdt.services.plumbing.lifecycle import exit_process

    try:
        code = main()
    except Exception:
        logging.getLogger(__name__).critical("gngdt stopped on an unexpected error",
                                             exc_info=True)
        code = 1
    exit_process(code)


if __name__ == "__main__":
    command()
