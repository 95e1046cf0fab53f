"""Real RGB-D image folders (../shared/data/rgbd, beside the repository) and the `gngdt record`
command that imports them, run in this process."""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

from gngdt.services import record as cli

#: the real RGB-D samples; absent when ../shared is (tests using them skip)
RGBD = Path(__file__).resolve().parents[3] / "shared" / "data" / "rgbd"
TUM = RGBD / "tum_fr1_xyz_dvo_examples"


def run_cli(*argv: str) -> int:
    """`gngdt record ARGV...` in this process; its exit status."""
    parser = argparse.ArgumentParser()
    cli.add_arguments(parser)
    return cli.main(parser.parse_args(list(argv)))


def build_tum_folder(root: Path) -> list[tuple[str, str]]:
    """A TUM-layout folder from the fr1 samples; returns (rgb stamp, depth stamp) pairs."""
    (root / "rgb").mkdir(parents=True)
    (root / "depth").mkdir()
    stamps = [
        ("1305031102.175304", "1305031102.160407"),
        ("1305031102.211214", "1305031102.226738"),
        ("1305031102.275326", "1305031102.262886"),
    ]
    rgb_lines = [
        "# color images",
        "# file: 'rgbd_dataset_freiburg1_xyz.bag'",
        "# timestamp filename",
    ]
    depth_lines = [
        "# depth maps",
        "# file: 'rgbd_dataset_freiburg1_xyz.bag'",
        "# timestamp filename",
    ]
    for index, (rgb_stamp, depth_stamp) in enumerate(stamps):
        shutil.copy(TUM / "color" / f"{index:06d}.png", root / "rgb" / f"{rgb_stamp}.png")
        shutil.copy(TUM / "depth" / f"{index:06d}.png", root / "depth" / f"{depth_stamp}.png")
        rgb_lines.append(f"{rgb_stamp} rgb/{rgb_stamp}.png")
        depth_lines.append(f"{depth_stamp} depth/{depth_stamp}.png")
    depth_lines.append("1305031109.000000 depth/unpaired.png")  # no colour near it: skipped
    (root / "rgb.txt").write_text("\n".join(rgb_lines) + "\n")
    (root / "depth.txt").write_text("\n".join(depth_lines) + "\n")
    return stamps
