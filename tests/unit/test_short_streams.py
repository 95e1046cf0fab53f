"""Short or poorly learned streams say so: objects at a stream's end, the run's summary."""

from __future__ import annotations

from pathlib import Path

from gngdt.core.learner.frame_learner import FrameLearner, LearnerConfig
from gngdt.io.deproject import Deprojector
from gngdt.io.mcap.reader import read_frames
from gngdt.schemas.status import LearnerStatusInfo, StreamEndInfo
from gngdt.services.run.summary import RunFacts, format_summary

SMALL_RECORDING = Path(__file__).resolve().parents[2] / "recordings" / "tabletop_small.mcap"


def test_a_stream_shorter_than_the_confirmation_ends_with_objects() -> None:
    """Objects need object_confirm_frames learned frames in a row while the network grows; a
    stream of fewer frames would end with none. Once it is over (the settled, final network),
    every segment of min_cluster_size nodes is an object."""
    learner = FrameLearner("camera", LearnerConfig())
    deproject = Deprojector()
    frames = list(read_frames(SMALL_RECORDING))[:2]
    assert len(frames) < learner.options.object_confirm_frames
    for frame in frames:
        learner.learn(*deproject(frame.depth, frame.color, frame.intrinsics))
    learned = learner.learned_frame()
    assert len(learner.objects(learned)) == 0  # nothing confirmed yet ...
    final = learner.objects(learned, final=True)
    assert len(final) >= 2  # ... but the stream's final network has its objects
    assert (final.node_counts >= learner.options.min_cluster_size).all()


def test_the_summary_says_how_much_was_learned_and_warns_when_little() -> None:
    end = StreamEndInfo(frames_sent=50, last_frame_sequence=49)
    few = LearnerStatusInfo(frames_used=3, frames_dropped=47, nodes=1000, steps=530_000)
    text = format_summary(RunFacts(few, end, destination="runs/x.rrd", node_budget=1000))
    assert "frames learned:     3 of 50 sent (6%)" in text
    assert "every frame sent:   50 = 3 learned + 47 dropped + 0 malformed + 0 refused" in text
    assert "WARNING: the learner kept up with only 6% of the frames" in text
    most = LearnerStatusInfo(frames_used=45, frames_dropped=5, nodes=1000, steps=450_000)
    text = format_summary(RunFacts(most, end, destination="runs/x.rrd", node_budget=1000))
    assert "45 of 50 sent (90%)" in text and "WARNING" not in text
    small = LearnerStatusInfo(frames_used=3, nodes=62, steps=30_000)
    text = format_summary(RunFacts(small, StreamEndInfo(frames_sent=3, last_frame_sequence=2),
                                   destination="runs/x.rrd", node_budget=1000))
    assert "WARNING: the network has 62 of its 1000 nodes" in text
