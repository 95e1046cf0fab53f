"""Learning steps budgeted by time (`gngdt_core.frame_budget`): a frame gets the steps that fit in
its share of the frame interval, fewer on a busy machine, never fewer than the minimum; and the
learner takes the steps it is given."""

from __future__ import annotations

import numpy as np
import pytest

from gngdt_core.frame_budget import MIN_INTERVAL_S, StepBudget
from gngdt_core.frame_learner import FrameLearner, LearnerConfig, LearnerOptions

MS = 1_000_000  # ns


def fed(budget: StepBudget, frames: int, interval_ms: float, steps_per_s: float,
        overhead_s: float) -> StepBudget:
    """``frames`` frames arriving every ``interval_ms``, each learned at ``steps_per_s`` and
    taking ``overhead_s`` besides."""
    for index in range(frames):
        budget.arrived(index, round(1_000 * MS + index * interval_ms * MS))
        steps = budget.next().steps
        seconds = steps / steps_per_s
        budget.learned(steps, seconds, seconds + overhead_s)
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
