"""The logger's loop: zenoh in, outputs out, until every camera's stream is over."""

from __future__ import annotations

import argparse
import logging
from collections.abc import Callable
from typing import TYPE_CHECKING

from gngdt.io.outputs import Output
from gngdt.schemas.wire import ALL_KEYS, ANY_CAMERA, logger_alive_key, topic
from gngdt.services.logger.cameras import Cameras, CaptureWatch
from gngdt.services.logger.dispatch import Dispatcher
from gngdt.services.logger.inbox import LOGGED_STREAMS, Inbox
from gngdt.services.plumbing import lifecycle
from gngdt.services.plumbing.report import write_report
from gngdt.services.plumbing.session import ZenohSetupError, open_session

if TYPE_CHECKING:
    import zenoh

log = logging.getLogger(__name__)


def receive_in_order(raw: list[Output], inbox: Inbox) -> Callable[[zenoh.Sample], None]:
    """One callback for every sample: the raw outputs first, then the loop's inbox. The loop
    ends on the learner's settled network: by then the raw outputs have it too, which they
    might not through subscribers of their own (each hands samples over on its own thread)."""

    def receive(sample: zenoh.Sample) -> None:
        for output in raw:
            output.receive(sample)
        inbox.put(sample)

    return receive


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
    raw = [output for output in outputs if output.raw]
    if raw:  # --mcap, --foxglove: one subscriber, so they have each sample before the loop
        declared = [session.declare_subscriber(ALL_KEYS, receive_in_order(raw, inbox))]
    else:  # only the streams the loop logs: a learner builds its scene only for a subscriber
        declared = [session.declare_subscriber(topic(ANY_CAMERA, stream), inbox.put)
                    for stream in LOGGED_STREAMS]
    captures = CaptureWatch()
    declared.append(session.liveliness().declare_subscriber(
        CaptureWatch.KEY, captures.on_token, history=True))
    try:
        with lifecycle.graceful() as stop:
            # ready (`gngdt run` waits for it) only once a stop signal would end the loop cleanly
            declared.append(session.liveliness().declare_token(
                logger_alive_key(str(session.zid()))))
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
