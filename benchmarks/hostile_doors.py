"""Issue 38's attacks on the new doors, for ``bench_hostile.py`` (and the inputs the tests make of
them): calibrations with absurd finite values, a /tf stamp in 2038, RealSense files made odd on
purpose, environment settings out of range, checkpoints and poses beyond the workspace,
Foxglove clients that never read, a ROS 2 image flood, credentials a killed run left behind.
Each is a real command (or a real service under a real client) on small generated input; per
attack, the exit code of every process, the peak RSS of the largest one, whether a traceback
reached the user, and what was learned or kept."""

from __future__ import annotations

import base64
import json
import os
import shutil
import signal
import socket
import sqlite3
import struct
import subprocess
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from hostile_inputs import input_attacks
from hostile_trust import GNGDT, Attack, Ran, attack, line_with, run

# ----------------------------------------------------------------- RealSense files, made odd


def cdr_string(text: str) -> bytes:
    """A std_msgs/String in CDR: the little-endian header, the length with its NUL, the bytes."""
    data = text.encode() + b"\0"
    return b"\x00\x01\x00\x00" + struct.pack("<I", len(data)) + data


def cdr_text(data: bytes) -> str:
    """The text of a std_msgs/String in CDR."""
    (length,) = struct.unpack("<I", data[4:8])
    return data[8:8 + length - 1].decode()


def rewrite_stream_info(path: Path, streams: str, edit) -> Path:
    """Apply ``edit`` (str -> str) to the SDK's stream descriptions (``width=..;height=..;
    fx=..``) of ``streams`` (``Color``, ``Depth``, or ``_`` for both) in a ``.db3``."""
    with sqlite3.connect(path) as connection:
        rows = connection.execute(
            "SELECT m.id, m.data FROM messages m JOIN topics t ON t.id = m.topic_id "
            "WHERE t.name LIKE ?", (f"%{streams}%_0/camera_info",)).fetchall()
        if not rows:
            raise ValueError(f"{path}: no stream description of {streams!r}")
        for row_id, data in rows:
            connection.execute("UPDATE messages SET data = ? WHERE id = ?",
                               (cdr_string(edit(cdr_text(data))), row_id))
    return path


def odd_realsense_recordings(folder: Path, frames: int = 3) -> dict[str, Path]:
    """A small recording the SDK wrote (64x48), and copies made odd: every stream claiming
    65535x65535; the colour one 65535x48000 with a plausible field of view (over any pixel
    limit); the image metadata rows stored as TEXT instead of BLOB. Needs pyrealsense2."""
    from gngdt.io.synth.realsense import write_virtual_recording

    folder.mkdir(parents=True, exist_ok=True)
    base = write_virtual_recording(folder / "base.db3", frames=frames, width=64, height=48).path
    made = {"base": base}

    def copy(name: str) -> Path:
        made[name] = shutil.copy(base, folder / f"{name}.db3")
        return made[name]

    size = "width=64;height=48"
    rewrite_stream_info(copy("huge"), "_", lambda text: text.replace(
        size, "width=65535;height=65535"))
    wide = {size: "width=65535;height=48000", "fx=61.5499992": "fx=60000",
            "fy=61.5750008": "fy=60000", "ppx=31.8624992": "ppx=32767",
            "ppy=24.2374992": "ppy=24000"}

    def widen(text: str) -> str:
        for old, new in wide.items():
            text = text.replace(old, new)
        return text

    rewrite_stream_info(copy("wide"), "Color", widen)
    with sqlite3.connect(copy("text_metadata")) as connection:
        connection.execute("UPDATE messages SET data = CAST(data AS TEXT) WHERE topic_id IN "
                           "(SELECT id FROM topics WHERE name LIKE '%metadata')")
    return made


def device_file_attacks(folder: Path) -> list[Attack]:
    """`gngdt run` on each odd RealSense recording: exit 2 naming the file, no traceback."""
    rows = []
    recordings = odd_realsense_recordings(folder / "recordings")
    for name in ("huge", "wide", "text_metadata"):
        ran = run([*GNGDT, "run", str(recordings[name]), "--fast", "--save",
                   str(folder / f"{name}.rrd")], folder / f"run-{name}.log")
        rows.append(attack(f"RealSense .db3: {name.replace('_', ' ')}", {"run": ran},
                           line_with(ran.output, "refused", "BLOB", "SDK")[:90]))
    return rows


# ------------------------------------------------------------------ Foxglove clients, hostile


def _frame(sock: socket.socket) -> tuple[int, bytes]:
    """One WebSocket frame from the server (unmasked): (opcode, payload)."""
    def exactly(count: int) -> bytes:
        data = b""
        while len(data) < count:
            chunk = sock.recv(count - len(data))
            if not chunk:
                raise ConnectionError("the server closed the connection")
            data += chunk
        return data

    first, second = exactly(2)
    length = second & 0x7F
    if length == 126:
        (length,) = struct.unpack(">H", exactly(2))
    elif length == 127:
        (length,) = struct.unpack(">Q", exactly(8))
    return first & 0x0F, exactly(length)


def _masked_text(text: str) -> bytes:
    """A client's (masked) WebSocket text frame."""
    data, mask = text.encode(), os.urandom(4)
    header = bytes([0x81, 0x80 | 126]) + struct.pack(">H", len(data)) if len(data) > 125 \
        else bytes([0x81, 0x80 | len(data)])
    return header + mask + bytes(byte ^ mask[index % 4] for index, byte in enumerate(data))


def stalled_foxglove_client(port: int, timeout_s: float = 10.0) -> socket.socket:
    """A client that subscribes to every channel the server advertises, then never reads: the
    WebSocket handshake (subprotocol foxglove.sdk.v1), frames read until the advertisement,
    one subscribe message, and a small receive buffer. A server that ends the connection
    before (a client refused) leaves it as it is."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=timeout_s)
    try:
        _subscribe_all(sock, port)
    except (ConnectionError, OSError):
        pass  # refused: the socket is closed by the server
    return sock


def _subscribe_all(sock: socket.socket, port: int) -> None:
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall((f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
                  f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                  "Sec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: foxglove.sdk.v1\r\n"
                  "\r\n").encode())
    response = b""
    while b"\r\n\r\n" not in response:
        chunk = sock.recv(1)
        if not chunk:
            raise ConnectionError("no WebSocket handshake")
        response += chunk
    channels: list[int] = []
    while not channels:
        opcode, payload = _frame(sock)
        if opcode == 1:
            message = json.loads(payload)
            if message.get("op") == "advertise":
                channels = [channel["id"] for channel in message["channels"]]
    subscriptions = [{"id": index + 1, "channelId": channel}
                     for index, channel in enumerate(channels)]
    sock.sendall(_masked_text(json.dumps({"op": "subscribe", "subscriptions": subscriptions})))


class ReadingClients:
    """``count`` well-behaved Foxglove clients on one asyncio thread: each subscribes to every
    channel and reads (and discards) everything, until `close`; ``received`` bytes in all."""

    def __init__(self, port: int, count: int) -> None:
        import asyncio

        self.received = 0
        self.connected = 0
        self._loop = asyncio.new_event_loop()
        self._stop = asyncio.Event()
        self._thread = threading.Thread(target=self._loop.run_until_complete,
                                        args=(self._run(port, count),), daemon=True)
        self._thread.start()

    async def _run(self, port: int, count: int) -> None:
        import asyncio

        await asyncio.gather(*(self._client(port) for _ in range(count)),
                             return_exceptions=True)

    async def _client(self, port: int) -> None:
        import asyncio

        from websockets.asyncio.client import connect

        async with connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"],
                           max_size=None, compression=None, open_timeout=30) as websocket:
            self.connected += 1
            subscribed = set()
            while not self._stop.is_set():
                try:
                    frame = await asyncio.wait_for(websocket.recv(), 0.5)
                except TimeoutError:
                    continue
                if isinstance(frame, str):
                    message = json.loads(frame)
                    if message.get("op") == "advertise":
                        new = [c["id"] for c in message["channels"] if c["id"] not in subscribed]
                        subscribed.update(new)
                        await websocket.send(json.dumps({"op": "subscribe", "subscriptions": [
                            {"id": channel, "channelId": channel} for channel in new]}))
                else:
                    self.received += len(frame)

    def close(self) -> None:
        self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(30)


@dataclass
class FoxglovePhases:
    """The logger's resident memory (MB) through a Foxglove attack: before any client, its
    peak while ``stalled`` clients that never read were connected and once they were gone (after
    ``settle_s``), the same for ``reading`` well-behaved ones; how many of each the logger still
    had connected at the end of their phase (dropped ones are not); its log."""

    before_mb: float = 0.0
    stalled_peak_mb: float = 0.0
    after_stalled_mb: float = 0.0
    reading_peak_mb: float = 0.0
    after_reading_mb: float = 0.0
    stalled_left: int = 0
    reading_received_mb: float = 0.0
    log: str = ""


def served_clients(port: int) -> int:
    """Established TCP connections accepted on local ``port`` of this machine (the server's
    ends: a client's own end has an ephemeral local port), from /proc."""
    count = 0
    for table in ("tcp", "tcp6"):
        for line in Path(f"/proc/net/{table}").read_text().splitlines()[1:]:
            columns = line.split()
            if int(columns[1].rsplit(":", 1)[1], 16) == port and columns[3] == "01":
                count += 1
    return count


def foxglove_under_clients(folder: Path, recording: Path, stalled: int, reading: int,
                           hold_s: float = 20.0, settle_s: float = 20.0,
                           logger_options: tuple[str, ...] = (),
                           stalled_gone_within_s: float = 0.0) -> FoxglovePhases:
    """A logger serving Foxglove (``--foxglove``) while `gngdt capture --loop` replays
    ``recording`` at its rate: ``stalled`` clients that never read for ``hold_s`` (and up to
    ``stalled_gone_within_s`` more until the logger has let them all go), closed, then
    ``reading`` well-behaved ones for ``hold_s``, closed; its memory through it all (sampled
    from /proc every 0.1 s: VmHWM is the peak)."""
    from procstat import gngdt, status_mb, wait_until

    from gngdt.services.plumbing.session import free_tcp_port, open_config, router_config

    endpoint, port = f"tcp/127.0.0.1:{free_tcp_port()}", free_tcp_port()
    router = open_config(router_config([endpoint]), what="router")
    log = folder / "logger.log"
    logger = gngdt("log", "--save", str(folder / "foxglove.rrd"), "--foxglove", "--bind",
                   f"127.0.0.1:{port}", "--keep-running", "--zenoh-connect", endpoint,
                   *logger_options, log=log)
    capture = gngdt("capture", str(recording), "--loop", "--realtime", "--zenoh-connect",
                    endpoint, log=folder / "capture.log")
    phases = FoxglovePhases()
    try:
        wait_until(lambda: "serving Foxglove" in log.read_text(), 180, "the logger")
        time.sleep(5.0)  # streaming, no client yet
        phases.before_mb = status_mb(logger.pid, "VmRSS")
        sockets = [stalled_foxglove_client(port) for _ in range(stalled)]
        time.sleep(hold_s)
        gone_by = time.monotonic() + stalled_gone_within_s
        while served_clients(port) and time.monotonic() < gone_by:
            time.sleep(0.1)
        phases.stalled_left = served_clients(port)
        phases.stalled_peak_mb = status_mb(logger.pid, "VmHWM")
        for sock in sockets:
            sock.close()
        time.sleep(settle_s)
        phases.after_stalled_mb = status_mb(logger.pid, "VmRSS")
        clients = ReadingClients(port, reading)
        time.sleep(hold_s)
        phases.reading_peak_mb = status_mb(logger.pid, "VmHWM")
        phases.reading_received_mb = clients.received / 1e6
        clients.close()
        time.sleep(settle_s)
        phases.after_reading_mb = status_mb(logger.pid, "VmRSS")
    finally:
        for process in (capture, logger):
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGINT)
                try:
                    process.wait(60)
                except subprocess.TimeoutExpired:
                    os.killpg(process.pid, signal.SIGKILL)
                    process.wait()
        router.close()
    phases.log = log.read_text(errors="replace")
    return phases


def foxglove_attacks(folder: Path) -> list[Attack]:
    """40 Foxglove clients that never read, then 50 that do, on a logger serving a 640x480
    recording at 30 fps: its peak and its memory once they left."""
    recording = folder / "tabletop.mcap"
    made = run([*GNGDT, "record", "synth", "--scene", "tabletop", "--frames", "30", "--out",
                str(recording)], folder / "record.log")
    if made.code:
        raise SystemExit(f"cannot make the recording: {made.output[-500:]}")
    phases = foxglove_under_clients(folder, recording, stalled=40, reading=50)
    ran = Ran(0, max(phases.stalled_peak_mb, phases.reading_peak_mb), phases.log)
    note = (f"RSS {phases.before_mb:.0f} MB before; 40 never reading: peak "
            f"{phases.stalled_peak_mb:.0f}, {phases.after_stalled_mb:.0f} 20 s after, "
            f"{phases.stalled_left} left connected; 50 reading: peak "
            f"{phases.reading_peak_mb:.0f}, {phases.after_reading_mb:.0f} 20 s after "
            f"({phases.reading_received_mb:.0f} MB read)")
    return [attack("Foxglove: 40 clients never reading, then 50 reading", {"log": ran}, note)]


# ---------------------------------------------------------------------- a ROS 2 image flood


@dataclass
class FloodOutcome:
    """The bridge's memory (MB) through an image flood: before, its peak, ``settle_s`` after;
    images offered; its log."""

    before_mb: float
    peak_mb: float
    after_mb: float
    #: of ``after_mb``, shared memory (the bridge's publishing pools, by design)
    after_shared_mb: float
    images: int
    log: str


def bridge_under_flood(folder: Path, seconds: float = 10.0, width: int = 1920,
                       height: int = 1080, settle_s: float = 10.0) -> FloodOutcome:
    """`gngdt ros2` while a ROS 2 camera (gngdt's own node, as bench_ros2) floods it with colour
    and depth images of ``width`` x ``height`` and their CameraInfo as fast as it can for
    ``seconds``, then nothing for ``settle_s``."""
    import numpy as np
    from procstat import gngdt, status_mb, wait_until

    from gngdt.core.sensor.geometry import CameraIntrinsics
    from gngdt.io.ros2 import messages as m
    from gngdt.io.ros2.node import Ros2Node
    from gngdt.schemas.wire import BRIDGE, DEFAULT_CAMERA, alive_key
    from gngdt.services.plumbing.session import (
        client_config,
        free_tcp_port,
        open_config,
        router_config,
    )

    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    router = open_config(router_config([endpoint]), what="router")
    session = open_config(client_config([endpoint]))
    log = folder / "ros2.log"
    bridge = gngdt("ros2", "--zenoh-connect", endpoint, log=log)
    node = None
    try:
        wait_until(lambda: any(True for _ in session.liveliness().get(
            alive_key(DEFAULT_CAMERA, BRIDGE), timeout=1.0)), 60, "the bridge")
        node = Ros2Node(session, "flood")
        topics = {"info": ("/camera/camera/color/camera_info", m.CAMERA_INFO),
                  "color": ("/camera/camera/color/image_raw", m.IMAGE),
                  "depth": ("/camera/camera/aligned_depth_to_color/image_raw", m.IMAGE)}
        publishers = {name: node.create_publisher(topic, kind, m.type_hash(kind))
                      for name, (topic, kind) in topics.items()}
        wait_until(lambda: all(p.has_subscribers for p in publishers.values()), 30,
                   "the bridge's subscriptions")
        camera = CameraIntrinsics(width, height, 0.8 * width, 0.8 * width, width / 2,
                                  height / 2)
        rng = np.random.default_rng(0)
        color = rng.integers(0, 256, (height, width, 3), dtype=np.uint8)
        depth = rng.integers(500, 4000, (height, width), dtype=np.uint16)
        time.sleep(2.0)
        before = status_mb(bridge.pid, "VmRSS")
        images, deadline = 0, time.monotonic() + seconds
        while time.monotonic() < deadline:
            stamp = time.time_ns()
            publishers["info"].publish(m.encode_camera_info(m.CameraInfo(stamp, "optical",
                                                                         camera)), stamp)
            for name, pixels, encoding in (("color", color, "rgb8"), ("depth", depth, "16UC1")):
                publishers[name].publish(m.encode_image(pixels, encoding, stamp_ns=stamp,
                                                        frame_id="optical"), stamp)
                images += 1
        time.sleep(settle_s)
        outcome = FloodOutcome(before, status_mb(bridge.pid, "VmHWM"),
                               status_mb(bridge.pid, "VmRSS"),
                               status_mb(bridge.pid, "RssShmem"), images, "")
    finally:
        if node is not None:
            node.close()
        bridge.send_signal(signal.SIGINT)
        try:
            bridge.wait(30)
        except subprocess.TimeoutExpired:
            bridge.kill()
            bridge.wait()
        session.close()
        router.close()
    outcome.log = log.read_text(errors="replace")
    return outcome


def flood_attacks(folder: Path) -> list[Attack]:
    """The ROS 2 bridge flooded with 1920x1080 images for 10 s: its peak, and 10 s after."""
    outcome = bridge_under_flood(folder)
    ran = Ran(0, outcome.peak_mb, outcome.log)
    return [attack("ROS 2 image flood (1920x1080, 10 s)", {"ros2": ran},
                   f"{outcome.images} images; RSS {outcome.before_mb:.0f} MB before, "
                   f"{outcome.after_mb:.0f} MB 10 s after ({outcome.after_shared_mb:.0f} MB "
                   "of it its shared-memory publishing pools)")]


# ----------------------------------------------------------------------------- all of them
def door_attacks(folder: Path | None = None) -> list[Attack]:
    """Every attack of issue 38, in a fresh folder; one row each."""
    folder = folder or Path(tempfile.mkdtemp(prefix="bench-doors-"))
    rows = input_attacks(folder)
    for part in (device_file_attacks, foxglove_attacks, flood_attacks):
        part_folder = folder / part.__name__
        part_folder.mkdir()
        rows += part(part_folder)
    print(f"logs: {folder}")
    return rows
