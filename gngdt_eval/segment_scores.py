"""Scores of a predicted segmentation against ground-truth segments (the labelled sets' usual
score, ``../shared/data/labelled/README.md``).

Pixels scored: those with valid depth and a ground-truth label (label 0 = no label, no depth
there, is ignored). Ground truth: 1 = background and supporting surfaces (not scored, but its
pixels count in the predicted segments' sizes), k >= 2 = one segment each. Prediction: 0 = no
segment, j >= 1 = segment j. For each ground-truth segment G its best IoU is the largest
``|G ∩ P| / |G ∪ P|`` over the predicted segments P, so pixels of G left unassigned count against
it. A set's mean best IoU and recalls are over all its ground-truth segments (pooled over frames).

Failure modes, per ground-truth segment G and the predicted segment P that covers most of it
(`object_failures`; an object can fail in more than one way): **fragmented** when P covers less
than 80 % of G; **merged** when P also covers more than 20 % of another ground-truth segment;
**missed** when no predicted segment has G as its majority (G vanished into the background, into
another object's segment, or was left unassigned).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

#: ground-truth labels: 0 ignored, 1 background, >= 2 segments
IGNORED, BACKGROUND, FIRST_SEGMENT = 0, 1, 2
RECALL_THRESHOLDS = (0.5, 0.75)
#: fragmented: the segment covering most of an object covers less than this share of it
FRAGMENTED_BELOW = 0.8
#: merged: that segment covers more than this share of a second object
MERGED_ABOVE = 0.2
FAILURES = ("fragmented", "merged", "missed")


@dataclass(frozen=True)
class FailureCounts:
    """How many ground-truth segments failed in each way (`object_failures`), of ``objects``."""

    objects: int = 0
    fragmented: int = 0
    merged: int = 0
    missed: int = 0

    def __add__(self, other: FailureCounts) -> FailureCounts:
        return FailureCounts(*(a + b for a, b in zip(self.as_tuple(), other.as_tuple(),
                                                     strict=True)))

    def as_tuple(self) -> tuple[int, int, int, int]:
        return (self.objects, self.fragmented, self.merged, self.missed)

    def as_dict(self) -> dict[str, int]:
        return dict(zip(("objects", *FAILURES), self.as_tuple(), strict=True))


@dataclass(frozen=True)
class FrameScore:
    """Scores of one frame."""

    #: ground-truth segment id -> its best IoU
    best_iou: dict[int, float]
    #: predicted segments with at least one scored pixel
    n_predicted: int
    #: ground-truth segment id -> how it failed (a subset of `FAILURES`; empty: it did not)
    failures: dict[int, frozenset[str]] = field(default_factory=dict)

    @property
    def failure_counts(self) -> FailureCounts:
        return FailureCounts(len(self.best_iou), *(
            sum(name in failed for failed in self.failures.values()) for name in FAILURES))

    @property
    def mean_best_iou(self) -> float:
        return float(np.mean(list(self.best_iou.values()))) if self.best_iou else float("nan")

    def recall(self, threshold: float) -> float:
        """Share of the ground-truth segments whose best IoU is >= ``threshold``."""
        if not self.best_iou:
            return float("nan")
        return float(np.mean([iou >= threshold for iou in self.best_iou.values()]))


def score_frame(truth: np.ndarray, predicted: np.ndarray,
                valid: np.ndarray | None = None) -> FrameScore:
    """Best IoU of every ground-truth segment of one frame.

    truth: (H, W) int ground-truth labels; predicted: (H, W) int labels (0 = none); valid:
    (H, W) bool pixels with depth (default: all); pixels with truth 0 are never scored.
    """
    overlap = overlap_matrix(truth, predicted, valid)
    truth_sizes = overlap.sum(axis=1)
    predicted_sizes = overlap.sum(axis=0)
    best = {}
    for segment in range(FIRST_SEGMENT, overlap.shape[0]):
        if truth_sizes[segment] == 0:
            continue
        intersection = overlap[segment, 1:]  # predicted 0 = no segment: never a match
        union = truth_sizes[segment] + predicted_sizes[1:] - intersection
        best[segment] = float((intersection / union).max()) if intersection.size else 0.0
    return FrameScore(best, int(np.count_nonzero(predicted_sizes[1:])),
                      object_failures(overlap))


def overlap_matrix(truth: np.ndarray, predicted: np.ndarray,
                   valid: np.ndarray | None = None) -> np.ndarray:
    """(T, P) int64 pixel counts: ``[t, p]`` scored pixels of ground truth t predicted as p
    (T, P: the largest labels + 1; arguments as `score_frame`)."""
    if truth.shape != predicted.shape:
        raise ValueError(f"ground truth {truth.shape} and prediction {predicted.shape} differ")
    scored = truth != IGNORED
    if valid is not None:
        scored &= valid
    truth_ids = truth[scored].astype(np.int64)
    predicted_ids = predicted[scored].astype(np.int64)
    if truth_ids.size and (truth_ids.min() < 0 or predicted_ids.min() < 0):
        raise ValueError("labels must be >= 0")
    n_truth = int(truth_ids.max(initial=0)) + 1
    n_pred = int(predicted_ids.max(initial=0)) + 1
    return np.bincount(truth_ids * n_pred + predicted_ids,
                       minlength=n_truth * n_pred).reshape(n_truth, n_pred)


def object_failures(overlap: np.ndarray) -> dict[int, frozenset[str]]:
    """Per ground-truth segment (rows >= 2 with pixels) of an `overlap_matrix`, how it failed:
    "fragmented", "merged", "missed" (module docstring); empty when it came out whole."""
    truth_sizes = overlap.sum(axis=1)
    objects = overlap[FIRST_SEGMENT:, 1:]  # predicted 0 = no segment
    # share of each object (row) in each predicted segment (column); whether it is the majority
    # of that segment's scored pixels (background included)
    share_of_object = objects / np.maximum(truth_sizes[FIRST_SEGMENT:, None], 1)
    majority = 2 * overlap[FIRST_SEGMENT:, 1:] > overlap[:, 1:].sum(axis=0)[None, :]
    failures = {}
    for row in range(objects.shape[0]):
        segment = FIRST_SEGMENT + row
        if truth_sizes[segment] == 0:
            continue
        failed = set()
        best = int(np.argmax(objects[row])) if objects.shape[1] else -1
        if best < 0 or share_of_object[row, best] < FRAGMENTED_BELOW:
            failed.add("fragmented")
        if best >= 0 and objects[row, best] > 0:
            others = np.delete(share_of_object[:, best], row)
            if (others > MERGED_ABOVE).any():
                failed.add("merged")
        if not majority[row].any():
            failed.add("missed")
        failures[segment] = frozenset(failed)
    return failures


def summarize_scores(scores: Sequence[FrameScore]) -> dict[str, float]:
    """Over a set: mean best IoU and recalls pooled over every ground-truth segment, mean
    predicted and ground-truth segments per frame."""
    ious = np.array([iou for score in scores for iou in score.best_iou.values()])
    summary = {"mean_best_iou": float(ious.mean()) if ious.size else float("nan")}
    for threshold in RECALL_THRESHOLDS:
        summary[recall_key(threshold)] = (float((ious >= threshold).mean()) if ious.size
                                          else float("nan"))
    summary["segments_per_frame"] = (float(np.mean([s.n_predicted for s in scores]))
                                     if scores else float("nan"))
    summary["truth_segments"] = int(ious.size)
    counts = sum((score.failure_counts for score in scores), FailureCounts())
    summary.update({name: value for name, value in counts.as_dict().items()
                    if name != "objects"})
    return summary


def recall_key(threshold: float) -> str:
    """``"recall_50"`` for 0.5, ``"recall_75"`` for 0.75."""
    return f"recall_{round(threshold * 100)}"
