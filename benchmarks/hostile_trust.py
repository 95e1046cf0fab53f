"""Issue 24's attacks, for ``bench_hostile.py``: poses that contradict their depth, one service
speaking for another, an unbounded MCAP recorder, runs that collide, odd files, depth in the
wrong unit. Each is a real command (or `gngdt run`) on small generated input; per attack, the
exit code of every process, the peak RSS of the largest one (itself and its children, from
the kernel's own account), whether a traceback reached the user, and for the roles attack how
many messages a role may not publish were recorded."""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

REPO_ROOT = Path(__file__).resolve().parents[1]
GNGDT = [sys.executable, "-m", "gngdt.services.cli"]

#: runs a command, then prints the peak RSS of its process tree (every descendant it waited)
PEAK_RSS = (
    "import resource, subprocess, sys\n"
    "code = subprocess.call(sys.argv[1:])\n"
    "print('peak_rss_kb', resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, flush=True)\n"
    "sys.exit(code)\n"
)
#: runs gngdt with every file it writes stopped at 3 MB (EFBIG, as a full disk's ENOSPC)
FULL_DISK = (
    "import os, resource, signal, sys\n"
    "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
    "resource.setrlimit(resource.RLIMIT_FSIZE, (3_000_000, 3_000_000))\n"
    "os.execv(sys.executable, [sys.executable, '-m', 'gngdt.services.cli', *sys.argv[1:]])\n"
)


@dataclass
class Attack:
    """One attack's outcome (see the module docstring)."""

    label: str
    codes: dict[str, int]
    peak_mb: float
    traceback: bool
    note: str = ""
    #: messages recorded that their role may not publish (None: not this attack's question)
    forbidden: int | None = None


@dataclass
class Ran:
    code: int
    peak_mb: float
    output: str


def start(command: list[str], log: Path, cwd: Path = REPO_ROOT) -> subprocess.Popen:
    """``command`` (a gngdt one by default) started with its peak RSS measured, output to
    ``log``."""
    with open(log, "wb") as output:
        return subprocess.Popen([sys.executable, "-c", PEAK_RSS, *command], cwd=cwd,
                                stdout=output, stderr=subprocess.STDOUT,
                                start_new_session=True)


def finish(process: subprocess.Popen, log: Path, timeout_s: float = 600) -> Ran:
    try:
        code = process.wait(timeout_s)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        code = process.wait()
    text = log.read_text(errors="replace")
    peak = next((int(line.split()[1]) / 1024 for line in text.splitlines()
                 if line.startswith("peak_rss_kb ")), 0.0)
    return Ran(code, peak, text)


def run(command: list[str], log: Path, timeout_s: float = 600, cwd: Path = REPO_ROOT) -> Ran:
    return finish(start(command, log, cwd), log, timeout_s)


def attack(label: str, ran: dict[str, Ran], note: str = "",
           forbidden: int | None = None) -> Attack:
    row = Attack(label, {name: item.code for name, item in ran.items()},
                 max(item.peak_mb for item in ran.values()),
                 any("Traceback" in item.output for item in ran.values()), note, forbidden)
    print(f"  {label}: exit {row.codes}, {row.peak_mb:.0f} MB{', ' + note if note else ''}",
          flush=True)
    return row


def line_with(text: str, *needles: str) -> str:
    """The first line of ``text`` holding one of ``needles``, after its log prefix and the
    file it names."""
    for line in text.splitlines():
        if any(needle in line for needle in needles):
            if " ERROR " in line or " WARNING " in line or " INFO " in line:
                line = line.split(": ", 1)[-1]
            # the reason, without the file it names (the benchmark made it)
            return re.sub(r"^(?:gngdt segment: |checkpoint )?(?:\S*/\S*: )+", "", line).strip()
    return ""


# ----------------------------------------------------------------------------- inputs
def walk_frames(count: int = 30):
    from gngdt.io.synth.render import render_scene

    return list(render_scene("tabletop_walk", count, width=160, height=120))


def w_first(pose: np.ndarray) -> np.ndarray:
    """What a reader taking x y z w makes of a pose written w x y z."""
    from gngdt.core.sensor.geometry import matrix_to_pose, pose_to_matrix

    translation, (x, y, z, w) = matrix_to_pose(pose)
    return pose_to_matrix(translation, [w, x, y, z])


def recording(path: Path, frames, pose_of=None) -> Path:
    """``frames`` into a gngdt MCAP, each pose replaced by ``pose_of(index, pose)``."""
    from gngdt.io.frame import CameraPose
    from gngdt.io.mcap.writer import RecordingWriter

    with RecordingWriter(path) as writer:
        for index, frame in enumerate(frames):
            if pose_of is not None:
                frame = replace(frame, pose=CameraPose(pose_of(index, frame.pose.matrix),
                                                       "world"))
            writer.write_frame(frame)
    return path


def image_folder(folder: Path, frames, depth_of=None) -> Path:
    """A redwood folder of ``frames`` (depth through ``depth_of``), camera.json and poses
    written w x y z in poses_wxyz.txt."""
    import cv2

    from gngdt.core.sensor.geometry import matrix_to_pose

    (folder / "color").mkdir(parents=True)
    (folder / "depth").mkdir()
    lines = []
    for index, frame in enumerate(frames):
        cv2.imwrite(str(folder / "color" / f"{index:06d}.png"), frame.color[..., ::-1])
        depth = frame.depth if depth_of is None else depth_of(frame.depth)
        cv2.imwrite(str(folder / "depth" / f"{index:06d}.png"), depth)
        (tx, ty, tz), (x, y, z, w) = matrix_to_pose(frame.pose.matrix)
        lines.append(f"{tx:.6f} {ty:.6f} {tz:.6f} {w:.9f} {x:.9f} {y:.9f} {z:.9f}")
    k = frames[0].intrinsics
    (folder / "camera.json").write_text(json.dumps(
        {"fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy, "depth_scale": 1000.0}))
    (folder / "poses_wxyz.txt").write_text("\n".join(lines) + "\n")
    return folder


def run_summary(ran: Ran) -> str:
    learned = line_with(ran.output, "frames learned:")
    rejected = line_with(ran.output, "poses rejected:")
    return f"{learned}; {rejected[:70]}" if rejected else learned


# ----------------------------------------------------------------------------- 24.1 poses
def pose_attacks(folder: Path) -> list[Attack]:
    frames = walk_frames()
    rows = []
    images = image_folder(folder / "walk", frames[:24])
    ran = run([*GNGDT, "record", "images", "--format", "redwood", str(images), "--poses",
               str(images / "poses_wxyz.txt"), "--out", str(folder / "wxyz-import.mcap")],
              folder / "import-wxyz.log")
    cause = line_with(ran.output, "likely cause").split("likely cause: ", 1)[-1]
    rows.append(attack("poses written w,x,y,z: record images", {"record": ran},
                       f"likely cause: {cause[:60]}"))
    cases = {
        "poses written w,x,y,z: gngdt run": lambda index, pose: w_first(pose),
        "one /tf at 1e18 m after 5 good frames": lambda index, pose: (
            pose if index != 5 else np.block([[pose[:3, :3], np.full((3, 1), 1e18)],
                                              [pose[3:]]])),
        "contradictory /tf: every 3rd frame turned 180 deg": lambda index, pose: (
            pose if index % 3 != 2 else pose @ np.diag([-1.0, 1.0, -1.0, 1.0])),
    }
    for label, pose_of in cases.items():
        path = recording(folder / f"{len(rows)}.mcap", frames, pose_of)
        ran = run([*GNGDT, "run", str(path), "--rate", "0.5", "--save",
                   str(folder / f"{len(rows)}.rrd")], folder / f"run-{len(rows)}.log")
        rows.append(attack(label, {"run": ran}, run_summary(ran)))
    return rows


def crafted_checkpoint(path: Path, **changes) -> Path:
    """A learner checkpoint with a valid digest whose state is changed as ``changes`` say."""
    from gngdt.core import GNGDT
    from gngdt.io.checkpoints import save_checkpoint

    rng = np.random.default_rng(0)
    model = GNGDT(max_nodes=60, utility_k=1000.0, replay_share=0.3, random_state=0)
    for x in (0.0, 0.1):
        pose = np.eye(4)
        pose[0, 3] = x
        model.partial_fit(rng.uniform([-0.5, -0.4, 2.0], [0.5, 0.4, 2.0], (2000, 3)),
                          rng.integers(0, 256, (2000, 3)), n_steps=3000, camera_pose=pose)
    state = model.get_state()
    for key, change in changes.items():
        state[key] = change(state[key].copy())
    save_checkpoint(path, state, {"camera": "camera", "counters": {}})
    return path


def checkpoint_attacks(folder: Path) -> list[Attack]:
    def scaled(array):
        array[0] = 1e18
        return array

    files = {
        "checkpoint: rehearsal memory at 1e18 m": {"memory_positions": scaled},
        "checkpoint: memory_offered 2**63-10": {
            "memory_offered": lambda _: np.array(2**63 - 10)},
        "checkpoint: version 99": {"version": lambda _: np.array(99)},
        "checkpoint: version a string": {"version": lambda _: np.array("4")},
        "checkpoint: float16 memory": {"memory_positions": lambda a: a.astype(np.float16)},
    }
    rows = []
    for index, (label, changes) in enumerate(files.items()):
        path = crafted_checkpoint(folder / f"checkpoint-{index}.npz", **changes)
        ran = run([*GNGDT, "learn", "--checkpoint", str(path), "--router-wait", "0"],
                  folder / f"learn-{index}.log", 120)
        rows.append(attack(label, {"learn": ran}, line_with(ran.output, "ERROR")[:90]))
    ran = run([*GNGDT, "learn", "--checkpoint", "/sys/fs/gngdt/learner.npz",
               "--router-wait", "0"], folder / "learn-read-only.log", 120)
    rows.append(attack("checkpoint in a read-only folder", {"learn": ran},
                       line_with(ran.output, "ERROR")[:90]))
    return rows


# ----------------------------------------------------------------------------- 24.2 roles
def descendants(pid: int) -> list[int]:
    found = []
    for status in Path("/proc").glob("[0-9]*/status"):
        try:
            fields = dict(line.split(":\t", 1) for line in status.read_text().splitlines()
                          if ":\t" in line)
        except OSError:
            continue
        if int(fields.get("PPid", "0").strip()) == pid:
            child = int(status.parent.name)
            found += [child, *descendants(child)]
    return found


def run_credentials(wrapper_pid: int, timeout_s: float = 120) -> Path:
    """The private folder of the `gngdt run` under ``wrapper_pid`` (from a service's
    --zenoh-config), once its services are up."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        for pid in descendants(wrapper_pid):
            try:
                arguments = Path(f"/proc/{pid}/cmdline").read_bytes().decode().split("\0")
            except OSError:
                continue
            if "--zenoh-config" in arguments:
                return Path(arguments[arguments.index("--zenoh-config") + 1]).parent
        time.sleep(0.1)
    raise SystemExit("gngdt run's services did not come up")


def forge(folder: Path, role: str) -> None:
    """An end of stream put with ``role``'s credentials, and objects unless the role is the
    learner's (objects are its own stream), ten times each."""
    import zenoh

    from gngdt.schemas.status import encode_stream_end
    from gngdt.schemas.wire import ENCODING_SCENE_UPDATE, FrameStamp
    from gngdt.services.plumbing.session import client_config, open_config

    session = open_config(client_config(None, folder / f"{role}.json5"))
    block = zenoh.CongestionControl.BLOCK
    for sequence in range(10):
        attachment = FrameStamp(sequence, time.time_ns()).to_attachment()
        end = encode_stream_end(frames_sent=1, last_frame_sequence=0, recording="forged")
        session.put("gngdt/camera/eos", end.SerializeToString(), attachment=attachment,
                    congestion_control=block)
        if role != "learner":
            session.put("gngdt/camera/objects", b"forged objects", attachment=attachment,
                        encoding=ENCODING_SCENE_UPDATE, congestion_control=block)
    session.close()


def forged_in(mcap_path: Path) -> int:
    """Messages of the MCAP a role may not publish: the forgeries (each says so)."""
    from mcap.reader import make_reader

    with open(mcap_path, "rb") as file:
        return sum(b"forged" in message.data
                   for _, _, message in make_reader(file).iter_messages())


def role_attack(folder: Path) -> list[Attack]:
    path = recording(folder / "roles.mcap", walk_frames(12))
    log = folder / "run-roles.log"
    process = start([*GNGDT, "run", str(path), "--rate", "0.1", "--save",
                     str(folder / "roles.rrd"), "--mcap", str(folder / "roles-run.mcap")], log)
    credentials = run_credentials(process.pid)
    time.sleep(2.0)  # the capture is replaying
    for role in ("logger", "learner"):
        forge(credentials, role)
    ran = finish(process, log)
    return [attack("eos (+ objects) forged with the logger's / learner's credentials",
                   {"run": ran}, run_summary(ran), forged_in(folder / "roles-run.mcap"))]


# ----------------------------------------------------------------------------- 24.3 the MCAP
def flood(endpoint: str, key_of, payload: bytes, count: int, seconds: float = 60) -> int:
    """Put ``payload`` on ``key_of(i)`` ``count`` times (or for ``seconds``); how many."""
    from gngdt.schemas.wire import ENCODING_SCENE_UPDATE, FrameStamp
    from gngdt.services.plumbing.session import client_config, open_config

    session = open_config(client_config([endpoint]))
    deadline, sent = time.monotonic() + seconds, 0
    while sent < count and time.monotonic() < deadline:
        session.put(key_of(sent), payload, encoding=ENCODING_SCENE_UPDATE,
                    attachment=FrameStamp(sent, time.time_ns()).to_attachment())
        sent += 1
    session.close()
    return sent


def mcap_channels(path: Path) -> int:
    from mcap.reader import make_reader

    with open(path, "rb") as file:
        summary = make_reader(file).get_summary()
    return -1 if summary is None else len(summary.channels)


def logger_under(folder: Path, name: str, endpoint: str, feed, wrapper: list[str] | None = None
                 ) -> tuple[Ran, Path]:
    """A logger with --mcap on a fresh router, fed by ``feed(endpoint)``, then interrupted."""
    from gngdt.services.plumbing.session import open_config, router_config

    router = open_config(router_config([endpoint]), what="router")
    mcap_path, log = folder / f"{name}.mcap", folder / f"log-{name}.log"
    command = wrapper or GNGDT
    process = start([*command, "log", "--save", str(folder / f"{name}.rrd"), "--mcap",
                     str(mcap_path), "--keep-running", "--zenoh-connect", endpoint], log)
    deadline = time.monotonic() + 120
    while "recording to" not in log.read_text() and time.monotonic() < deadline:
        time.sleep(0.1)
    feed(endpoint)
    time.sleep(2.0)
    for pid in descendants(process.pid):
        os.kill(pid, signal.SIGINT)
    ran = finish(process, log, 120)
    router.close()
    return ran, mcap_path


def mcap_attacks(folder: Path) -> list[Attack]:
    from gngdt.services.plumbing.session import free_tcp_port

    rows = []
    scene = bytes(4 * 1024 * 1024)  # 4 MB scene updates, as fast as they go, for 10 s
    ran, path = logger_under(folder, "scene-flood", f"tcp/127.0.0.1:{free_tcp_port()}",
                             lambda ep: flood(ep, lambda i: "gngdt/camera/scene", scene,
                                              10**9, 10.0))
    rows.append(attack("scene flood (4 MB updates, 10 s) into --mcap", {"log": ran},
                       line_with(ran.output, "recorded ")[:90]))
    ran, path = logger_under(folder, "cameras", f"tcp/127.0.0.1:{free_tcp_port()}",
                             lambda ep: flood(ep, lambda i: f"gngdt/made-up-{i}/objects",
                                              b"\x0a\x00", 100_000))
    rows.append(attack("objects on 100,000 camera names into --mcap", {"log": ran},
                       f"{mcap_channels(path)} channels in the MCAP"))
    image = os.urandom(230_000)  # incompressible, as images are
    ran, path = logger_under(folder, "full-disk", f"tcp/127.0.0.1:{free_tcp_port()}",
                             lambda ep: flood(ep, lambda i: "gngdt/camera/color", image, 60,
                                              10.0), [sys.executable, "-c", FULL_DISK])
    from mcap.reader import make_reader

    with open(path, "rb") as file:
        readable = sum(1 for _ in make_reader(file).iter_messages())
    rows.append(attack("--mcap on a full disk (writes stop at 3 MB)", {"log": ran},
                       f"MCAP read back: {readable} messages; "
                       + line_with(ran.output, "stopped writing")[-60:]))
    return rows


# ----------------------------------------------------------------------------- 24.4 runs
def run_attacks(folder: Path) -> list[Attack]:
    from gngdt.services.plumbing.session import free_tcp_port

    rows = []
    path = recording(folder / "small.mcap", walk_frames(8))
    with socket.socket() as viewer:  # another run's viewer holds the port
        viewer.bind(("127.0.0.1", 0))
        viewer.listen()
        ran = run([*GNGDT, "run", str(path), "--serve", "--grpc-port",
                   str(viewer.getsockname()[1]), "--web-port", str(free_tcp_port())],
                  folder / "run-busy-port.log", 120)
    rows.append(attack("second gngdt run --serve on a busy port", {"run": ran},
                       line_with(ran.output, "in use")[:90]))
    first = run([*GNGDT, "run", str(path), "--fast", "--mcap", str(folder / "same.mcap"),
                 "--save", str(folder / "same.rrd")], folder / "run-first.log")
    second = run([*GNGDT, "run", str(path), "--fast", "--mcap", str(folder / "same.mcap")],
                 folder / "run-second.log")
    rows.append(attack("two runs on one --mcap path", {"first": first, "second": second},
                       line_with(second.output, "exists")[:90]))
    together = [start([*GNGDT, "run", str(path), "--fast"], folder / f"together-{i}.log",
                      cwd=folder) for i in range(2)]
    ran = {f"run {i}": finish(process, folder / f"together-{i}.log")
           for i, process in enumerate(together)}
    named = {item.output.split("rerun:", 1)[-1].split()[0] for item in ran.values()}
    rows.append(attack("two runs started in the same second", ran,
                       f"{len(named)} distinct .rrd named, {len(list((folder / 'runs').iterdir()))}"
                       " written"))
    return rows


# ----------------------------------------------------------------------------- 24.5 odd files
def long_pose_file(path: Path, lines: int) -> Path:
    line = "1305031102.175304 1.3405 0.6266 1.6575 0.6574 0.6126 -0.2949 -0.3248\n"
    with open(path, "w") as file:
        for _ in range(lines // 10_000):
            file.write(line * 10_000)
    return path


def png_claiming(width: int, height: int) -> bytes:
    import struct
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data)))

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2,
                                                             0, 0, 0))
            + chunk(b"IDAT", zlib.compress(bytes(64))) + chunk(b"IEND", b""))


def odd_file_attacks(folder: Path) -> list[Attack]:
    frames = walk_frames(24)
    images = image_folder(folder / "odd", frames[:3])
    record = [*GNGDT, "record", "images", "--format", "redwood", str(images), "--out",
              str(folder / "odd.mcap")]
    rows = []
    inputs = {
        "pose file of 10,000,000 lines": long_pose_file(folder / "long.txt", 10_000_000),
        "pose stamp Infinity": folder / "infinity.txt",
    }
    inputs["pose stamp Infinity"].write_text("1.0 0 0 0 0 0 0 1\nInfinity 0 0 0 0 0 0 1\n")
    for label, poses in inputs.items():
        ran = run([*record, "--poses", str(poses)], folder / f"record-{len(rows)}.log")
        rows.append(attack(label, {"record": ran}, line_with(ran.output, "ERROR")[:90]))
    segment = [*GNGDT, "segment"]
    cases = {
        "segment: a PNG claiming 100000x100000 pixels": lambda f: (
            f / "color" / "000001.png").write_bytes(png_claiming(100_000, 100_000)),
        "segment: a FIFO among the images": lambda f: [
            os.mkfifo(f / kind / "000009.png") for kind in ("color", "depth")],
        "segment: camera.json fx NaN": lambda f: (f / "camera.json").write_text(
            '{"fx": NaN, "fy": 100, "cx": 80, "cy": 60, "depth_scale": 1000}'),
        "segment: camera.json depth_scale NaN": lambda f: (f / "camera.json").write_text(
            '{"fx": 100, "fy": 100, "cx": 80, "cy": 60, "depth_scale": NaN}'),
    }
    for index, (label, damage) in enumerate(cases.items()):
        case = image_folder(folder / f"segment-{index}", frames[:3])
        damage(case)
        ran = run([*segment, str(case), "--out", str(folder / f"seg-{index}")],
                  folder / f"segment-{index}.log", 300)
        rows.append(attack(label, {"segment": ran},
                           (line_with(ran.output, "ERROR") or line_with(ran.output, "wrote"))
                           [:90]))
    tiny = tiny_folder(folder / "tiny", 20)
    ran = run([*segment, str(tiny), "--out", str(folder / "seg-tiny"), "--independent"],
              folder / "segment-tiny.log", 600)
    summary = json.loads((folder / "seg-tiny" / "summary.json").read_text()) \
        if ran.code == 0 else {"milliseconds": {"total": {"p50": float("nan")}}}
    rows.append(attack("segment: twenty 8x8 frames", {"segment": ran},
                       f"{summary['milliseconds']['total']['p50']:.0f} ms/frame p50"))
    return rows


def tiny_folder(folder: Path, frames: int) -> Path:
    import cv2

    (folder / "color").mkdir(parents=True)
    (folder / "depth").mkdir()
    rng = np.random.default_rng(0)
    for index in range(frames):
        cv2.imwrite(str(folder / "color" / f"{index:06d}.png"),
                    rng.integers(0, 256, (8, 8, 3), dtype=np.uint8))
        cv2.imwrite(str(folder / "depth" / f"{index:06d}.png"),
                    np.full((8, 8), 1000 + index, np.uint16))
    (folder / "camera.json").write_text(json.dumps(
        {"fx": 10.0, "fy": 10.0, "cx": 4.0, "cy": 4.0, "depth_scale": 1000.0}))
    return folder


# ----------------------------------------------------------------------------- 24.6 depth
def depth_attacks(folder: Path) -> list[Attack]:
    import cv2

    frames = walk_frames(3)
    pcl = folder / "float-depth"
    pcl.mkdir()
    for index, frame in enumerate(frames):
        stamp = f"frame_20240101T00000{index}.000000"
        cv2.imwrite(str(pcl / f"{stamp}_rgb.tiff"), frame.color[..., ::-1])
        cv2.imwrite(str(pcl / f"{stamp}_depth.tiff"), frame.depth.astype(np.float32) / 1000)
    rows = []
    ran = run([*GNGDT, "record", "images", "--format", "pcl-tiff", str(pcl), "--out",
               str(folder / "float.mcap")], folder / "record-float.log")
    rows.append(attack("depth TIFF of float32 metres", {"record": ran},
                       line_with(ran.output, "ERROR")[:90]))
    metres = image_folder(folder / "metres", frames,
                          lambda depth: np.rint(depth / 1000.0).astype(np.uint16))
    ran = run([*GNGDT, "record", "images", "--format", "redwood", str(metres), "--out",
               str(folder / "metres.mcap")], folder / "record-metres.log")
    rows.append(attack("depth PNG of metres as uint16", {"record": ran},
                       (line_with(ran.output, "depth ") + " / "
                        + line_with(ran.output, "WARNING"))[:90]))
    return rows


# ----------------------------------------------------------------------------- all of them
def trust_attacks(folder: Path | None = None) -> list[Attack]:
    """Every attack of issue 24, in a fresh folder; one row each."""
    folder = folder or Path(tempfile.mkdtemp(prefix="bench-trust-"))
    rows = []
    for part in (pose_attacks, checkpoint_attacks, role_attack, mcap_attacks, run_attacks,
                 odd_file_attacks, depth_attacks):
        part_folder = folder / part.__name__
        part_folder.mkdir()
        rows += part(part_folder)
    print(f"logs: {folder}")
    return rows


def print_trust(rows: list[Attack], title: str = "issue 24 attack") -> bool:
    """The table; True when every target is met (no process above 1 GB, no traceback reaching
    a user, nothing recorded that a role may not publish)."""
    print(f"\n{title:<62}{'exit codes':<26}{'peak RSS':>9}  tb  note")
    for row in rows:
        codes = " ".join(f"{name} {code}" for name, code in row.codes.items())
        note = row.note if row.forbidden is None else f"forged recorded: {row.forbidden}; " \
            + row.note
        print(f"{row.label[:61]:<62}{codes:<26}{row.peak_mb:>6.0f} MB  "
              f"{'yes' if row.traceback else 'no':<3} {note[:110]}")
    worst = max(row.peak_mb for row in rows)
    tracebacks = sum(row.traceback for row in rows)
    forged = sum(row.forbidden or 0 for row in rows)
    met = worst <= 1024 and not tracebacks and not forged
    print(f"\ntargets: peak RSS <= 1024 MB: {worst:.0f} MB; tracebacks: {tracebacks}; "
          f"recorded what a role may not publish: {forged} -> {'met' if met else 'MISSED'}")
    return met
