"""Learning steps budgeted by time (`gngdt.core.learner.frame_budget`): a frame gets the steps that
fit in its share of the frame interval, fewer on a busy machine, never fewer than the minimum;
publishing takes at most its share of the time; a learner that waits for its frames is not
starved by their pace; and the learner takes the steps it is given."""

from __future__ import annotations

import numpy as np
import pytest

from gngdt.core.learner.frame_budget import MIN_INTERVAL_S, StepBudget
from gngdt.core.learner.frame_learner import FrameLearner, LearnerConfig, LearnerOptions

MS = 1_000_000  # ns


def fed(budget: StepBudget, frames: int, interval_ms: float, steps_per_s: float,
        overhead_s: float, publish_s: float = 0.0) -> StepBudget:
    """``frames`` frames arriving every ``interval_ms`` (the learner never idle), each learned
    at ``steps_per_s`` and taking ``overhead_s`` besides; publishing takes ``publish_s``."""
    clock = 0.0
    for index in range(frames):
        sensor_ns = round(1_000 * MS + index * interval_ms * MS)
        budget.arrived(index, sensor_ns)
        steps = budget.next().steps
        seconds = steps / steps_per_s
        budget.learned(steps, seconds, seconds + overhead_s)
        clock += seconds + overhead_s
        if budget.publish_due(clock, sensor_ns):
            budget.published(publish_s, clock, sensor_ns)
            clock += publish_s
    return budget


def test_a_quiet_machine_learns_every_frame_fully() -> None:
    budget = fed(StepBudget(0.8, 1_000, 10_000), 20, 40.0, 2e6, 0.005)
    assert budget.next().steps == 10_000
    assert budget.last.interval_s == pytest.approx(0.040)
    assert budget.last.seconds == pytest.approx(0.040 * 0.8 - 0.005)


def test_a_busy_machine_learns_fewer_steps_within_the_frame_time() -> None:
    """A third of the speed and twice the other work: the frame's work still fits its share."""
    budget = fed(StepBudget(0.8, 1_000, 10_000), 20, 40.0, 2e5, 0.010)
    steps = budget.next().steps
    assert 1_000 < steps < 10_000
    assert steps / 2e5 + 0.010 == pytest.approx(0.8 * 0.040, rel=0.01)


def test_never_fewer_than_the_minimum_nor_more_than_the_maximum() -> None:
    starved = fed(StepBudget(0.8, 1_000, 10_000), 20, 33.3, 1e4, 0.05)  # overhead > interval
    assert starved.next().steps == 1_000 and starved.last.seconds == 0.0
    assert fed(StepBudget(0.8, 1_000, 10_000), 20, 1000.0, 2e5, 0.0).next().steps == 10_000


def test_the_interval_counts_dropped_frames_and_has_a_floor() -> None:
    budget = StepBudget(1.0, 1, 10**9)
    for index, sequence in enumerate((0, 3, 6, 9)):  # every third frame reaches the learner
        budget.arrived(sequence, 1_000 * MS + index * 100 * MS)
    budget.learned(1_000, 0.001, 0.001)
    assert budget.next().interval_s == pytest.approx(0.1 / 3)
    fast = StepBudget(1.0, 1, 10**9)
    for index in range(5):  # replayed as fast as possible: a camera's frame time at least
        fast.arrived(index, 1_000 * MS + index * MS)
    fast.learned(1_000, 0.001, 0.001)
    assert fast.next().interval_s == MIN_INTERVAL_S


def test_publishing_takes_at_most_its_share_and_learning_gets_the_rest() -> None:
    """Publishing costs 20 ms: at 30 frames a second it happens every 80 ms (a quarter of the
    time), and a frame's learning gets what is left of its share."""
    budget = fed(StepBudget(0.8, 1_000, 10_000), 30, 40.0, 2e5, 0.005, publish_s=0.020)
    last = budget.last
    assert last.publish_period_s == pytest.approx(0.080)
    assert last.seconds == pytest.approx(0.8 * 0.040 - 0.005 - 0.020 * 0.040 / 0.080)
    assert budget.next().steps == int(2e5 * last.seconds)
    budget.published(0.020, 100.0, 5_000 * MS)
    assert not budget.publish_due(100.05, 6_000 * MS) and budget.publish_due(100.081, 6_000 * MS)


def test_a_learner_that_waits_for_its_frames_is_not_starved() -> None:
    """A producer in lockstep with the learner (the next frame only once this one is
    published): its pace is the learner's own, and the learner is ahead every time, so every
    frame gets all the steps and is published."""
    budget = StepBudget(0.8, 1_000, 10_000)
    clock = 0.0
    for index in range(20):
        budget.arrived(index, round(1_000 * MS + clock * 1e9), waited=index > 0)
        steps = budget.next().steps
        budget.learned(steps, steps / 2e5, steps / 2e5 + 0.02)
        clock += steps / 2e5 + 0.02
        assert budget.publish_due(clock, index * 33 * MS)
        budget.published(0.02, clock, index * 33 * MS)
        clock += 0.02
        assert steps == 10_000


def test_publications_follow_the_streams_clock_not_the_machines() -> None:
    """Every third frame of a 30 fps stream is published at 0.1 s, whatever the wall clock
    says (a replay paced by the learner is ahead on every frame), stamps that fall a little short
    of the period included, and again when the clock goes back (a looped file); a period shorter
    than the frames' publishes every frame."""
    def published(budget: StepBudget, jitter_ns: int) -> list[int]:
        chosen = []
        for index in range(30):
            sensor_ns = 1_000 * MS + round(index * 1e9 / 30) + (jitter_ns if index % 2 else 0)
            # a paced replay: never a frame dropped, and the learner not always seen waiting
            budget.arrived(index, sensor_ns, waited=index % 4 == 0)
            if budget.publish_due(float(index) * 1e-3, sensor_ns):
                budget.published(0.01, float(index), sensor_ns)
                chosen.append(index)
        return chosen

    every_third = list(range(0, 30, 3))
    budget = StepBudget(0.0, 1, 10, publish_every_s=0.1)
    assert published(budget, 0) == every_third
    assert published(budget, 0) == every_third  # the clock went back (a looped file): afresh
    assert published(StepBudget(0.0, 1, 10, publish_every_s=0.1), -MS) == every_third
    assert published(StepBudget(0.0, 1, 10, publish_every_s=1e-9), 0) == list(range(30))
    with pytest.raises(ValueError):
        StepBudget(0.0, 1, 10, publish_every_s=-1.0)


def test_a_learner_dropping_frames_keeps_publishing_to_its_share_on_the_streams_clock() -> None:
    """Frames dropped on the way (a live camera faster than the learner): a publication the
    stream's clock allows still waits for the learner's own period."""
    budget = fed(StepBudget(0.8, 1_000, 10_000, publish_every_s=0.1), 30, 40.0, 2e5, 0.005,
                 publish_s=0.020)
    budget.published(0.020, 100.0, 5_000 * MS)
    budget.arrived(1_000, 6_000 * MS)  # after a gap in the sequence numbers
    assert not budget.publish_due(100.05, 6_000 * MS) and budget.publish_due(100.081, 6_000 * MS)
    budget.published(0.020, 100.081, 6_000 * MS)
    budget.arrived(1_001, 6_040 * MS)  # the next in sequence
    assert not budget.publish_due(100.09, 6_040 * MS)  # 40 ms of stream time: not yet
    budget.arrived(1_002, 6_100 * MS)
    assert budget.publish_due(100.09, 6_100 * MS)  # none dropped: the stream's clock decides


def test_no_budget_before_the_first_measurements_or_when_off() -> None:
    assert StepBudget(0.8, 1_000, 10_000).next().steps == 10_000
    assert fed(StepBudget(0.0, 1_000, 10_000), 10, 33.3, 1e4, 0.02).next().steps == 10_000
    with pytest.raises(ValueError):
        StepBudget(0.8, 0, 10)
    with pytest.raises(ValueError):
        StepBudget(1.5, 1, 10)


def test_the_learner_learns_the_steps_it_is_given() -> None:
    rng = np.random.default_rng(0)
    positions = rng.uniform([-1, -1, 1], [1, 1, 2], (5_000, 3)).astype(np.float32)
    colors = rng.integers(0, 256, (5_000, 3), dtype=np.uint8)
    learner = FrameLearner("camera", LearnerConfig(options=LearnerOptions(
        samples_per_frame=4_000)))
    learner.learn(positions, colors)
    learner.learn(positions, colors, steps=1_500)
    assert learner.model.n_steps_ == 5_500
    assert learner.last_steps == 1_500 and learner.counters.learning_steps == 5_500
