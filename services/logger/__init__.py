"""Log every gngdt stream (gngdt/**) to rerun (a .rrd file by default, or a viewer) and, when
asked, every stream as it is to an MCAP file (--mcap) and to a live Foxglove WebSocket
(--foxglove).

The outputs are `gngdt.io.outputs`, behind one interface.

The logger stops on its own once every camera it knows of (from its first message, or from its
capture's liveliness token, whichever comes first) has ended its stream (eos) and its learner's
settled topology and settled status have arrived (in either order), or ``--eos-drain`` seconds
after that eos (or after its capture left without one).
"""

from __future__ import annotations

import argparse
import logging
from typing import TYPE_CHECKING

from gngdt.io.outputs.file_limits import FILE_LIMITS_TITLE, add_file_limit_arguments
from gngdt.io.outputs.rerun_output import RATES_TITLE, add_rate_arguments
from gngdt.services.logger.cameras import DEFAULT_MAX_CAMERAS
from gngdt.services.logger.inbox import DEFAULT_QUEUE_MB
from gngdt.services.plumbing.report import add_report_argument
from gngdt.services.plumbing.session import add_zenoh_arguments
from gngdt.services.plumbing.settings import OptionGroup, add_settings_argument

__all__ = ["DISPLAY", "EXAMPLES", "FILE_LIMITS", "SETTINGS", "add_arguments", "main"]

if TYPE_CHECKING:
    from gngdt.io.outputs import Output

log = logging.getLogger(__name__)

EXAMPLES = """examples:
  gngdt log                                   # saves runs/log-<time>.rrd
  gngdt log --save out.rrd                    # out.1.rrd if out.rrd exists (never overwritten)
  gngdt log --connect --url rerun+http://127.0.0.1:9876/proxy   # a running viewer
  gngdt log --stdout | rerun -
  gngdt log --mcap runs/all.mcap              # + every stream as it is, for Foxglove
  gngdt log --foxglove                        # + live to Foxglove at ws://127.0.0.1:8765
  gngdt log --foxglove --bind 0.0.0.0:8765    # ... from other machines (no authentication)
"""

#: what the logger puts into the .rrd, declared once (by the rerun output) for `gngdt log` and
#: `gngdt run`
DISPLAY = OptionGroup(RATES_TITLE, add_rate_arguments)
#: how large its files may grow, and the free disk they leave (declared by the rerun output)
FILE_LIMITS = OptionGroup(FILE_LIMITS_TITLE, add_file_limit_arguments)
#: the option groups a settings file (``--settings``) may hold
SETTINGS = [DISPLAY, FILE_LIMITS]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from gngdt.io.outputs import OUTPUTS

    for output in OUTPUTS:
        output.add_arguments(parser)
    parser.add_argument("--eos-drain", type=float, default=10.0, metavar="SECONDS",
                        help="after an end-of-stream, wait at most this long for the last "
                        "topology (default 10)")
    parser.add_argument("--keep-running", action="store_true",
                        help="do not stop at end-of-stream (only on SIGINT/SIGTERM)")
    parser.add_argument("--overwrite", action="store_true",
                        help="write --save and --mcap over existing files (default: an existing "
                        "file is kept and <name>.1.rrd / .1.mcap written beside it)")
    limits = parser.add_argument_group("limits (what arrives beyond them is refused, counted)")
    limits.add_argument("--max-cameras", type=int, default=DEFAULT_MAX_CAMERAS, metavar="N",
                        help=f"cameras logged at most (default {DEFAULT_MAX_CAMERAS})")
    limits.add_argument("--max-queue-mb", type=int, default=DEFAULT_QUEUE_MB, metavar="MB",
                        help="messages held while the logger is busy, in MB (default "
                        f"{DEFAULT_QUEUE_MB}); the oldest make room")
    add_report_argument(parser, "each output, where it went and why it stopped early, if it "
                        "did")
    add_settings_argument(parser)
    add_zenoh_arguments(parser)


def build_outputs(args: argparse.Namespace) -> list[Output]:
    """Every registered output (`gngdt.io.outputs.OUTPUTS`) the options ask for; on an error
    (ValueError, OSError) the ones already made are closed."""
    from gngdt.io import outputs as registry

    for kind in registry.OUTPUTS:  # what cannot work is said before any output opens
        kind.check_args(args)
    made: list[Output] = []
    try:
        for kind in registry.OUTPUTS:
            output = kind.from_args(args)
            if output is not None:
                made.append(output)
    except (ValueError, OSError):
        for output in made:
            output.close()
        raise
    return made


def main(args: argparse.Namespace) -> int:
    from gngdt.io.outputs.rerun_sinks import exit_now_if_stuck
    from gngdt.services.logger.run import run_logger

    if args.max_queue_mb < 0 or args.max_cameras < 1:
        log.error("--max-queue-mb must be >= 0 and --max-cameras >= 1, got %s and %s",
                  args.max_queue_mb, args.max_cameras)
        return 2
    try:
        outputs = build_outputs(args)
    except (ValueError, OSError) as error:
        log.error("%s", error)
        return 2
    if not args.stdout:  # with --stdout, standard output is rerun's stream
        for output in outputs:
            print(output.describe(), flush=True)
    code = run_logger(args, outputs)
    stuck = any(getattr(output, "stuck", False) for output in outputs)
    return exit_now_if_stuck(stuck, code)
