"""Where the logger's streams go, behind one interface (`base.Output`): rerun (a .rrd or a
viewer), an MCAP recording, a live Foxglove WebSocket.

A new output is one module with an `Output` subclass and one line in `OUTPUTS`: the logger adds
its options to ``gngdt log`` and drives every output the options ask for.
"""

from gngdt.io.outputs.base import Output, StreamSample, split_key
from gngdt.io.outputs.foxglove import FoxgloveOutput
from gngdt.io.outputs.mcap import McapOutput
from gngdt.io.outputs.rerun_output import RerunOutput

#: every output the logger knows, in the order their options are shown
OUTPUTS: tuple[type[Output], ...] = (RerunOutput, McapOutput, FoxgloveOutput)

__all__ = ["OUTPUTS", "Output", "StreamSample", "split_key"]
