"""The moving camera in the world, as a run's .rrd holds it: docs/camera_in_world.png.

Runs ``gngdt run synth:tabletop_walk:N`` (the kitchen-like scene a camera walks past), copies
the .rrd's data chunks unchanged into a file whose blueprint is the figure's (one 3D view from
above and behind the walk: the cloud, the learned nodes and the camera, its frustum with its
image on it, at its last pose, the world's up as the poses say), and shows that in rerun's web
viewer in headless Chromium (`screenshot_viewer`). Only the layout is the figure's own. Needs what
`screenshot_viewer` needs (Chromium, playwright-core)::

    python docs/make_camera_figure.py --out docs/camera_in_world.png
"""

from __future__ import annotations

import argparse
import logging
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO_ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from screenshot_viewer import screenshot  # noqa: E402

log = logging.getLogger("make_camera_figure")
#: where the figure's view stands and looks (world frame of the scene: z up, metres)
EYE = (-1.0, -3.6, 2.5)
TARGET = (0.5, 0.1, 0.6)


def with_figure_layout(rrd: Path, out: Path) -> None:
    """``rrd``'s data chunks, as they are, into ``out`` with the figure's blueprint: one 3D view
    of the world, the camera's frustum large enough to see its image."""
    import rerun as rr
    import rerun.blueprint as rrb
    from rerun.chunk import RrdReader

    view = rrb.Spatial3DView(
        name="the walking camera in the world", origin="world",
        contents=["world/points", "world/gng/nodes", "world/gng/edges/pos", "world/camera",
                  "world/camera/image/rgb"],
        eye_controls=rrb.EyeControls3D(position=EYE, look_target=TARGET, eye_up=(0, 0, 1)),
        overrides={"world/camera": [rr.Pinhole.from_fields(image_plane_distance=0.5)]},
        background=rrb.Background(color=[22, 24, 28]))
    layout = rrb.Blueprint(view, rrb.TimePanel(state="collapsed"), collapse_panels=True)
    figure = rr.RecordingStream("gngdt-figure")
    figure.save(str(out), default_blueprint=layout)
    figure.send_chunks(RrdReader(str(rrd)).stream())
    figure.flush()
    figure.disconnect()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                     epilog=__doc__.split("::", 1)[1],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=150, help="frames of the walk (30 fps)")
    parser.add_argument("--out", type=Path, default=HERE / "camera_in_world.png")
    parser.add_argument("--timeout", type=float, default=300.0, metavar="SECONDS")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    with tempfile.TemporaryDirectory(prefix="gngdt-figure-") as folder:
        rrd, figure = Path(folder) / "walk.rrd", Path(folder) / "figure.rrd"
        completed = subprocess.run(
            [sys.executable, "-m", "gngdt.services.cli", "run",
             f"synth:tabletop_walk:{args.frames}",
             "--save", str(rrd)], cwd=REPO_ROOT, check=False)
        if completed.returncode != 0:
            log.error("gngdt run failed (exit %d)", completed.returncode)
            return 1
        with_figure_layout(rrd, figure)
        status = screenshot(figure, args.out, 1600, 1000, args.timeout)
    log.info("wrote %s%s", args.out, "" if status == 0 else " (the viewer never finished)")
    return status


if __name__ == "__main__":
    raise SystemExit(main())
