"""Issue 35, "say what happened": what a run, a service or a report tells the person at the
terminal -- refusals, addresses, assumptions and counts -- checked where no process is needed
(the processes' side: tests/process/test_say_what_happened_processes.py)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from helpers.summaries import every_frame_sent

from gngdt.schemas.status import LearnerStatusInfo, StreamEndInfo
from gngdt.services.cli import main
from gngdt.services.run.observe import LearnerAcks
from gngdt.services.run.summary import RunFacts, format_summary

REPO_ROOT = Path(__file__).resolve().parents[2]


# ------------------------------------------------------------------ 7: unknown options
@pytest.mark.parametrize("argv", [["run", "recordings/tabletop.mcap", "--foo"],
                                  ["eval", "paper", "--foo"], ["capture", "x.mcap", "--foo"]])
def test_an_unknown_option_prints_the_usage_of_the_subcommand_given_it(argv, capsys) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    said = capsys.readouterr().err
    prog = "gngdt " + " ".join(word for word in argv[:2] if not word.endswith(".mcap"))
    assert said.startswith(f"usage: {prog} ")
    assert f"{prog}: error: unrecognized arguments: --foo" in said


def test_run_help_and_the_contract_give_the_same_exit_statuses(capsys) -> None:
    from gngdt.services.run import verdict

    with pytest.raises(SystemExit):
        main(["run", "--help"])
    text = capsys.readouterr().out
    contract = (REPO_ROOT / "docs" / "contracts.md").read_text()
    codes = {verdict.DONE: "done", verdict.FAILED: "a service failed",
             verdict.INPUT_UNUSABLE: "the input is unusable",
             verdict.NOTHING_LEARNED: "the learner learned nothing",
             verdict.OUTPUT_STOPPED: "the .rrd or MCAP writer stopped early",
             verdict.INTERRUPTED: "interrupted"}
    assert len(set(codes)) == 6
    for code, meaning in codes.items():
        assert re.search(rf"^\s+{code}\s+{meaning}", text, re.MULTILINE), (code, text)
        assert f"{code} {meaning}" in " ".join(contract.split()), (code, meaning)


# ------------------------------------------------------------- 5: counts that add up
def _acks(**outcomes: int) -> LearnerAcks:
    acks = LearnerAcks()
    for outcome, count in outcomes.items():
        for _ in range(count):
            acks.add(outcome.replace("_", " "), f"why {outcome}")
    return acks


@pytest.mark.parametrize("paced", [False, True])
def test_every_frame_sent_is_accounted_for_each_kind_named(paced: bool) -> None:
    end = StreamEndInfo(frames_sent=60, last_frame_sequence=59,
                        frames_without_cloud={"no camera pose at its time": 2})
    acks = _acks(learned=11, posed=34, pose_rejected=3, malformed=1)
    status = LearnerStatusInfo(frames_used=11, frames_dropped=12, nodes=500, steps=10**6)
    text = format_summary(RunFacts(status, end, acks, "runs/x.rrd", paced=paced))
    sent, terms = every_frame_sent(text)
    assert sent == 60 == sum(terms.values())
    left = "left behind" if paced else "dropped"
    assert terms == {"learned": 11, "dropped": 0 if paced else 9, "malformed": 1, "refused": 3,
                     "posed, not learned": 34, "sent without a cloud": 2,
                     **({left: 9} if paced else {})}
    assert "frames learned:     11 of 60 sent (18%)" in text
    assert ("refused by learner: pose rejected 3 (the first: why pose_rejected); malformed 1 "
            "(the first: why malformed)") in text
    assert "sent without cloud: 2 frames: no camera pose at its time (2)" in text


def test_what_capture_refused_and_warned_about_is_in_the_summary() -> None:
    end = StreamEndInfo(frames_sent=0, frames_refused={
        "--camera-json is for 320x240, colour is 640x480": 60},
        warnings=["depth_scale=1000 units per metre assumed, ... --depth-scale"])
    text = format_summary(RunFacts(None, end, destination="runs/x.rrd"))
    assert ("refused by capture: 60 frames: --camera-json is for 320x240, colour is 640x480 "
            "(60)") in text
    assert "WARNING: depth_scale=1000 units per metre assumed, ... --depth-scale" in text


def test_a_capture_tally_counts_refusals_by_reason_and_says_each_once(caplog) -> None:
    from gngdt.io.errors import RecordingError
    from gngdt.services.capture_tally import CaptureTally

    tally = CaptureTally()
    for index in range(3):
        tally.bad_frame(RecordingError("x.mcap", index, "--camera-json is for 320x240"))
    tally.refuse("x.mcap: frame 3", "another reason")
    assert tally.refused == {"--camera-json is for 320x240": 3, "another reason": 1}
    said = [record.getMessage() for record in caplog.records]
    assert said == ["x.mcap: frame 0: --camera-json is for 320x240; skipped (frames refused for "
                    "this reason are counted, not said again)",
                    "x.mcap: frame 3: another reason; skipped (frames refused for this reason "
                    "are counted, not said again)"]
    assert tally.describe() == ("4 frames refused: --camera-json is for 320x240 (3); another "
                                "reason (1)")


# ------------------------------------------------------------- 4: units and layouts
def _redwood(folder: Path, frames: list, camera: dict | None, metres: bool = False) -> Path:
    """A colour/ + depth/ folder of ``frames`` (depth in metres, as uint16, with ``metres``),
    with ``camera`` as its camera.json (None: none)."""
    import cv2

    (folder / "color").mkdir(parents=True)
    (folder / "depth").mkdir()
    for index, frame in enumerate(frames):
        cv2.imwrite(str(folder / "color" / f"{index:06d}.png"), frame.color[..., ::-1])
        depth = np.round(frame.depth / 1000.0).astype(np.uint16) if metres else frame.depth
        cv2.imwrite(str(folder / "depth" / f"{index:06d}.png"), depth)
    if camera is not None:
        (folder / "camera.json").write_text(json.dumps(camera))
    return folder


@pytest.fixture(scope="module")
def small_frames() -> list:
    from gngdt.io.mcap.reader import read_frames

    return list(read_frames(REPO_ROOT / "recordings" / "tabletop_small.mcap"))[:2]


def test_every_camera_parameter_a_folder_is_read_with_unsaid_is_named_with_its_setter(
        tmp_path: Path, small_frames: list) -> None:
    from gngdt.io.sources import SourceOptions, open_source

    bare = _redwood(tmp_path / "bare", small_frames, None)
    intrinsics, depth_scale = open_source(bare).assumptions
    assert intrinsics.startswith("fx=525 fy=525 cx=319.5 cy=239.5 px assumed, the redwood "
                                 "layout's defaults")
    assert "camera.json is missing" in intrinsics and "--camera-json" in intrinsics
    assert depth_scale.startswith("depth_scale=1000 units per metre assumed")
    assert "TUM's frames use 5000" in depth_scale and "--depth-scale" in depth_scale
    assert "camera.json" in depth_scale
    k = small_frames[0].intrinsics
    lens = {"fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy}
    partial = _redwood(tmp_path / "partial", small_frames, lens)
    (only,) = open_source(partial).assumptions
    assert only.startswith("depth_scale=1000 units per metre assumed")
    assert open_source(partial, options=SourceOptions(depth_scale=1000.0)).assumptions == []
    full = _redwood(tmp_path / "full", small_frames, {**lens, "depth_scale": 1000.0})
    assert open_source(full).assumptions == []


def test_depth_in_another_unit_is_said_alike_by_segment(
        tmp_path: Path, small_frames: list, capsys) -> None:
    """`gngdt segment` on depth stored in metres as uint16 (0-4) warns with the one message
    `gngdt record images` and capture give (`depth_warning`); plausible depth says nothing."""
    from gngdt.core.sensor.depth import DepthRange
    from gngdt.io.import_checks import depth_warning

    k = small_frames[0].intrinsics
    camera = {"fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy, "depth_scale": 1000.0}
    folder = _redwood(tmp_path / "metres", small_frames, camera, metres=True)
    profile = tmp_path / "small.toml"
    profile.write_text("[gngdt]\nmax_nodes = 100\n[frames]\nsteps_first_frame = 2000\n"
                       "[learner]\nsamples_per_frame = 1000\n")
    assert main(["segment", str(folder), "--out", str(tmp_path / "out"), "--params",
                 str(profile)]) == 0
    depth = DepthRange()
    for frame in small_frames:
        depth.add(np.round(frame.depth / 1000.0).astype(np.uint16))
    warning = depth_warning(depth)
    assert re.match(r"the median depth is 0\.00\d m, outside the 0\.1-20 m", warning), warning
    assert "--depth-scale" in warning and "camera.json's depth_scale" in warning
    assert f"WARNING: {warning}" in capsys.readouterr().out
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["warnings"] == [warning]
    plausible = DepthRange()
    plausible.add(small_frames[0].depth)
    assert depth_warning(plausible) == ""


# ------------------------------------------------------------- 2: live outputs
def test_the_servers_addresses_are_the_ones_to_open() -> None:
    import argparse

    from gngdt.services.run.live import live_outputs

    args = argparse.Namespace(serve=True, foxglove=True, bind="0.0.0.0:18765", grpc_port=19876,
                              web_port=19090)
    viewer, foxglove = live_outputs(args)
    assert viewer.url == ("http://127.0.0.1:19090?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A19876"
                          "%2Fproxy")
    assert "rerun --connect rerun+http://127.0.0.1:19876/proxy" in viewer.how
    assert foxglove.url == "ws://127.0.0.1:18765"
    assert "Open connection > Foxglove WebSocket > ws://127.0.0.1:18765" in foxglove.how


def test_a_report_is_read_back_whole_or_not_at_all(tmp_path: Path) -> None:
    from gngdt.services.plumbing.report import read_report, write_report

    path = tmp_path / "log.report.json"
    assert read_report(path) == {}
    write_report(path, {"outputs": [{"where": "x.mcap", "stopped_early": "disk full"}]})
    assert read_report(path) == {"outputs": [{"where": "x.mcap", "stopped_early": "disk full"}]}
    assert list(tmp_path.iterdir()) == [path]  # no partial file left beside it
    path.write_text("[1, 2")
    assert read_report(path) == {}
