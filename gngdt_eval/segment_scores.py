"""Scores of a predicted segmentation against ground-truth segments (the labelled sets' usual
score, ``../shared/data/labelled/README.md``).

Pixels scored: those with valid depth and a ground-truth label (label 0 = no label, no depth
there, is ignored). Ground truth: 1 = background and supporting surfaces (not scored, but its
pixels count in the predicted segments' sizes), k >= 2 = one segment each. Prediction: 0 = no
segment, j >= 1 = segment j. For each ground-truth segment G its best IoU is the largest
``|G ∩ P| / |G ∪ P|`` over the predicted segments P, so pixels of G left unassigned count against
it. A set's mean best IoU and recalls are over all its ground-truth segments (pooled over frames).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

#: ground-truth labels: 0 ignored, 1 background, >= 2 segments
IGNORED, BACKGROUND, FIRST_SEGMENT = 0, 1, 2
RECALL_THRESHOLDS = (0.5, 0.75)


@dataclass(frozen=True)
class FrameScore:
    """Scores of one frame."""

    #: ground-truth segment id -> its best IoU
    best_iou: dict[int, float]
    #: predicted segments with at least one scored pixel
    n_predicted: int

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
    overlap = np.bincount(truth_ids * n_pred + predicted_ids,
                          minlength=n_truth * n_pred).reshape(n_truth, n_pred)
    truth_sizes = overlap.sum(axis=1)
    predicted_sizes = overlap.sum(axis=0)
    best = {}
    for segment in range(FIRST_SEGMENT, n_truth):
        if truth_sizes[segment] == 0:
            continue
        intersection = overlap[segment, 1:]  # predicted 0 = no segment: never a match
        union = truth_sizes[segment] + predicted_sizes[1:] - intersection
        best[segment] = float((intersection / union).max()) if intersection.size else 0.0
    return FrameScore(best, int(np.count_nonzero(predicted_sizes[1:])))


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
    return summary


def recall_key(threshold: float) -> str:
    """``"recall_50"`` for 0.5, ``"recall_75"`` for 0.75."""
    return f"recall_{round(threshold * 100)}"
