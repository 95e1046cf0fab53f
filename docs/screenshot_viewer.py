"""Screenshot a logged run as a person sees it: rerun's web viewer in headless Chromium.

Serves the .rrd with rerun's own web viewer on loopback (``rerun --serve-web --bind 127.0.0.1``
on free ports), opens it in headless Chromium through playwright-core and keeps the screenshot
once the viewer has really drawn the recording (see ``docs/screenshot/shoot.mjs``: the viewer is
WebAssembly drawing into a canvas, so the page's load event says nothing).

Needs Debian's ``chromium`` (``apt-get install chromium``) and playwright-core
(``npm ci --prefix docs/screenshot``)::

    gngdt run recordings/tabletop.mcap --save runs/tabletop.rrd
    python docs/screenshot_viewer.py runs/tabletop.rrd --out docs/viewer.png
"""

from __future__ import annotations

import argparse
import logging
import os
import shutil
import signal
import subprocess
import tempfile
import time
import urllib.error
import urllib.request
from pathlib import Path
from urllib.parse import quote

HERE = Path(__file__).resolve().parent
REPO_ROOT = HERE.parent

from gngdt.io.outputs.rerun_sinks import rerun_binary  # noqa: E402
from gngdt.services.plumbing.session import free_tcp_port  # noqa: E402

log = logging.getLogger("screenshot_viewer")


def wait_for_http(url: str, timeout_s: float) -> None:
    """Until ``url`` answers (rerun's web server has started), or RuntimeError."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            with urllib.request.urlopen(url, timeout=2):
                return
        except (urllib.error.URLError, ConnectionError):
            time.sleep(0.2)
    raise RuntimeError(f"rerun's web viewer did not answer at {url} within {timeout_s:.0f} s")


def screenshot(rrd: Path, out: Path, width: int, height: int, timeout_s: float) -> int:
    """Serve ``rrd`` on loopback, screenshot it into ``out``; the exit status of the browser step
    (0: the viewer drew the recording)."""
    if shutil.which("node") is None:
        raise RuntimeError("node is not installed (apt-get install nodejs)")
    if not (HERE / "screenshot" / "node_modules" / "playwright-core").is_dir():
        raise RuntimeError("playwright-core is missing: npm ci --prefix docs/screenshot")
    grpc_port, web_port = free_tcp_port(), free_tcp_port()
    with tempfile.TemporaryDirectory(prefix="gngdt-shot-") as config:
        # rerun writes its analytics config on first use: keep it out of the user's home
        env = dict(os.environ, XDG_CONFIG_HOME=config)
        # the binary itself (the `rerun` script would start it as a grandchild, left running
        # when the script is stopped), in a process group of its own, stopped as a whole below
        server = subprocess.Popen(
            [rerun_binary(), "--serve-web", str(rrd), "--bind", "127.0.0.1", "--port",
             str(grpc_port), "--web-viewer-port", str(web_port), "--hide-welcome-screen"],
            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
            start_new_session=True)
        try:
            viewer = f"http://127.0.0.1:{web_port}"
            wait_for_http(viewer, 60)
            source = quote(f"rerun+http://127.0.0.1:{grpc_port}/proxy", safe="")
            log.info("rerun serves %s at %s", rrd, viewer)
            return subprocess.run(
                ["node", str(HERE / "screenshot" / "shoot.mjs"), f"{viewer}/?url={source}",
                 str(out), str(width), str(height), str(int(timeout_s))],
                check=False).returncode
        finally:
            stop_group(server)


def stop_group(process: subprocess.Popen) -> None:
    """Stop ``process`` and everything it started (its process group): SIGTERM, then SIGKILL."""
    for signum, wait_s in ((signal.SIGTERM, 10.0), (signal.SIGKILL, None)):
        try:
            os.killpg(process.pid, signum)
        except ProcessLookupError:
            break
        try:
            process.wait(wait_s)
            break
        except subprocess.TimeoutExpired:
            continue


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                     epilog=__doc__.split("::", 1)[1],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("rrd", type=Path, help="a .rrd written by gngdt run / gngdt log")
    parser.add_argument("--out", type=Path, default=HERE / "viewer.png", help="PNG to write")
    parser.add_argument("--width", type=int, default=1600)
    parser.add_argument("--height", type=int, default=1000)
    parser.add_argument("--timeout", type=float, default=240.0, metavar="SECONDS",
                        help="give up waiting for the viewer to draw after this long")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    if not args.rrd.is_file():
        log.error("%s: no such file", args.rrd)
        return 2
    try:
        status = screenshot(args.rrd, args.out, args.width, args.height, args.timeout)
    except RuntimeError as error:
        log.error("%s", error)
        return 1
    if not args.out.is_file():
        log.error("no screenshot taken")
        return 1
    log.info("wrote %s%s", args.out, "" if status == 0 else " (the viewer never finished)")
    return status


if __name__ == "__main__":
    raise SystemExit(main())
