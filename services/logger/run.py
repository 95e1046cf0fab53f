"""The logger's loop: zenoh in, outputs out, until every camera's stream is over."""

from __future__ import annotations

import argparse
import logging

from gngdt.io.outputs import Output
from gngdt.schemas.wire import ALL_KEYS, ANY_CAMERA, logger_alive_key, topic
from gngdt.services.logger.cameras import Cameras, CaptureWatch
from gngdt.services.logger.dispatch import LOGGED_STREAMS, Dispatcher
from gngdt.services.logger.inbox import Inbox
from gngdt.services.plumbing import lifecycle
from gngdt.services.plumbing.report import write_report
from gngdt.services.plumbing.session import ZenohSetupError, open_session

log = logging.getLogger(__name__)

def run_logger(args: argparse.Namespace, outputs: list[Output]) -> int:
    """Subscribe to ``gngdt/**`` and drive ``outputs`` until stopped or every stream is over;
    the outputs are closed on the way out. The exit code."""
    dispatcher = Dispatcher(outputs, Cameras(args.max_cameras))
    inbox = Inbox(args.max_queue_mb * 1024 * 1024, dispatcher.wants)
    try:
        session = open_session(args)
    except ZenohSetupError:  # said by the command line, exit 1; the outputs close first
        for output in outputs:
            output.close()
        raise
    # only the streams the outputs log: a learner builds its scene only for a subscriber; raw
    # outputs (--mcap, --foxglove) subscribe to everything themselves
    declared = [session.declare_subscriber(topic(ANY_CAMERA, stream), inbox.put)
                for stream in LOGGED_STREAMS]
    declared += [session.declare_subscriber(ALL_KEYS, output.receive)
                 for output in outputs if output.raw]
    captures = CaptureWatch()
    declared.append(session.liveliness().declare_subscriber(
        CaptureWatch.KEY, captures.on_token, history=True))
    declared.append(session.liveliness().declare_token(logger_alive_key(str(session.zid()))))
    try:
        with lifecycle.graceful() as stop:
            while not stop.is_set():
                inbox.arrived.wait(0.05)
                for key, payload, attachment in inbox.take():
                    dispatcher.handle(key, payload, attachment)
                    tick(outputs)
                for camera, alive in captures.take():
                    dispatcher.capture_seen(camera, alive)
                tick(outputs)
                if not args.keep_running and dispatcher.cameras.all_finished(args.eos_drain):
                    break
    finally:
        for entity in reversed(declared):
            entity.undeclare()
        session.close()
        for key, payload, attachment in inbox.take():
            dispatcher.handle(key, payload, attachment)
        for output in outputs:
            output.close()
    stopped = "; ".join(f"{output.describe()}: stopped early: {output.stopped_early()}"
                        for output in outputs if output.stopped_early())
    log.info("logger done: %d malformed, %d dropped, %d oversized, %d refused (cameras beyond "
             "--max-cameras)%s", dispatcher.malformed, inbox.dropped, inbox.oversized,
             dispatcher.cameras.refused, f"; {stopped}" if stopped else "")
    write_report(getattr(args, "report", None), {
        "outputs": [{"output": type(output).__name__, "where": output.describe(),
                     "stopped_early": output.stopped_early()} for output in outputs],
        "malformed": dispatcher.malformed, "dropped": inbox.dropped})
    return 0


def tick(outputs: list[Output]) -> None:
    for output in outputs:
        output.tick()
