"""Persistent cluster ids: a cluster keeps its id from one labelling to the next.

Connected components are relabelled from scratch every frame (``clusters()`` numbers them by
size), but the nodes they are made of persist (``node_ids_``). `ClusterIds` carries identity by
node membership: each cluster of the new labelling takes the id of the earlier cluster it shares
the most nodes with, greedily by shared-node count, each id at most once. A split keeps the id on
the part holding most of the old nodes; a merge keeps the id of the larger contributor, but a
confirmed one's before one not confirmed yet (a fragment that split off and merges back). A cluster
seen no more is remembered for ``memory_frames`` labellings, so a cluster that dips below the
minimum size for a moment, or splits off again, gets its id back.

A cluster is *confirmed* once it has been seen in ``confirm_frames`` labellings in a row (and
stays confirmed while it is remembered): segments of a network that is still growing, and thin
fragments at creases and at the edge of the view, split off and merge back for a frame or two;
only clusters that persist are objects (``confirmed_``; the tracking-by-detection trackers' "min
hits", e.g. SORT's).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class _Track:
    """One persistent cluster: its id, member node ids (sorted int64), when it was last seen, in
    how many labellings in a row up to then, and whether it is confirmed."""

    track_id: int
    nodes: np.ndarray
    last_seen: int
    streak: int = 1
    confirmed: bool = False


class ClusterIds:
    """Gives the clusters of successive labellings of one network persistent int64 ids.

    min_overlap: a cluster takes an earlier id only if the nodes it shares with that cluster are
    at least this fraction of its nodes that belonged to any remembered cluster (new nodes do not
    count either way). memory_frames: labellings a vanished cluster is remembered for.
    max_tracks: most clusters remembered (the least recently seen are forgotten first), so memory
    stays bounded whatever the input. confirm_frames: labellings in a row a cluster must be seen
    in before it is confirmed (1: at once).

    After `update`: ``confirmed_`` (K,) bool, per label of that labelling, whether its cluster is
    confirmed.
    """

    def __init__(self, min_overlap: float = 0.5, memory_frames: int = 30,
                 max_tracks: int = 10_000, confirm_frames: int = 1) -> None:
        if not 0.0 < min_overlap <= 1.0:
            raise ValueError(f"min_overlap must be in (0, 1], got {min_overlap!r}")
        for name, value in (("memory_frames", memory_frames), ("max_tracks", max_tracks),
                            ("confirm_frames", confirm_frames)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        self.min_overlap = float(min_overlap)
        self.memory_frames = int(memory_frames)
        self.max_tracks = int(max_tracks)
        self.confirm_frames = int(confirm_frames)
        self.confirmed_ = np.zeros(0, dtype=bool)
        self._tracks: list[_Track] = []
        self._next_id = 0
        self._frame = 0

    @property
    def n_tracks_(self) -> int:
        """Clusters currently remembered (seen in the last ``memory_frames`` labellings)."""
        return len(self._tracks)

    def forget(self) -> None:
        """Drop every remembered cluster (a new network: its node ids mean other nodes); ids
        already given are never given again."""
        self._tracks = []

    def update(self, node_ids: np.ndarray, labels: np.ndarray) -> np.ndarray:
        """(K,) int64 persistent id of each label 0..K-1 of this labelling.

        node_ids: (N,) int64 persistent node ids; labels: (N,) int, -1 = no cluster, else 0..K-1
        (K = labels.max() + 1).
        """
        node_ids = np.asarray(node_ids, dtype=np.int64)
        labels = np.asarray(labels)
        if node_ids.ndim != 1 or labels.shape != node_ids.shape:
            raise ValueError(f"node_ids {node_ids.shape} and labels {labels.shape} must be "
                             "equal-length 1-D arrays")
        self._frame += 1
        n_labels = int(labels.max()) + 1 if labels.size else 0
        clustered = labels >= 0
        members = node_ids[clustered]
        member_labels = labels[clustered].astype(np.int64)
        assigned = np.full(n_labels, -1, dtype=np.int64)
        confirmed = np.zeros(n_labels, dtype=bool)
        for label, track in self._matches(members, member_labels, n_labels):
            assigned[label] = track.track_id
        by_id = {track.track_id: track for track in self._tracks}
        self._confirmed_absorb(members, member_labels, assigned, by_id)
        order = np.argsort(member_labels, kind="stable")
        bounds = np.searchsorted(member_labels[order], np.arange(n_labels + 1))
        for label in range(n_labels):
            nodes = np.sort(members[order[bounds[label]:bounds[label + 1]]])
            if nodes.size == 0:
                continue  # a label with no node: nothing to identify
            if assigned[label] < 0:
                assigned[label] = self._next_id
                self._next_id += 1
                track = _Track(int(assigned[label]), nodes, self._frame)
                by_id[track.track_id] = track
            else:
                track = by_id[int(assigned[label])]
                track.streak = track.streak + 1 if track.last_seen == self._frame - 1 else 1
                track.nodes, track.last_seen = nodes, self._frame
            track.confirmed = track.confirmed or track.streak >= self.confirm_frames
            confirmed[label] = track.confirmed
        self._tracks = sorted(
            (track for track in by_id.values()
             if self._frame - track.last_seen < self.memory_frames),
            key=lambda track: (-track.last_seen, track.track_id))[: self.max_tracks]
        self.confirmed_ = confirmed
        return assigned

    def _confirmed_absorb(self, members: np.ndarray, member_labels: np.ndarray,
                          assigned: np.ndarray, by_id: dict[int, _Track]) -> None:
        """A confirmed cluster that merged with a fragment not yet confirmed keeps its id even
        when the fragment brought more nodes: a label whose match is unconfirmed (or none) takes
        the id of a confirmed, unmatched cluster that ``min_overlap`` of its surviving nodes
        went into (most shared first). Segments of a growing network split and merge back; the
        object must not vanish until its fragment's id is confirmed. ``assigned`` is updated."""
        taken = set(assigned[assigned >= 0].tolist())
        offers = []
        for track in self._tracks:
            if not track.confirmed or track.track_id in taken:
                continue
            surviving = np.isin(members, track.nodes)
            if not surviving.any():
                continue
            shares = np.bincount(member_labels[surviving])
            label = int(shares.argmax())
            if shares[label] >= self.min_overlap * surviving.sum():
                offers.append((int(shares[label]), label, track.track_id))
        for _, label, track_id in sorted(offers, key=lambda offer: (-offer[0], offer[2])):
            current = int(assigned[label])
            if current >= 0 and by_id[current].confirmed:
                continue
            assigned[label] = track_id

    def _matches(self, members: np.ndarray, member_labels: np.ndarray,
                 n_labels: int) -> list[tuple[int, _Track]]:
        """(label, track) pairs: greedily by shared nodes, then recency, then the older id."""
        if not self._tracks or members.size == 0:
            return []
        track_nodes = np.concatenate([track.nodes for track in self._tracks])
        track_index = np.repeat(np.arange(len(self._tracks)),
                                [track.nodes.size for track in self._tracks])
        order = np.argsort(track_nodes, kind="stable")
        track_nodes, track_index = track_nodes[order], track_index[order]
        lo = np.searchsorted(track_nodes, members, side="left")
        hi = np.searchsorted(track_nodes, members, side="right")
        counts = hi - lo
        # every (member node, track holding it) pair; a node may be in a live and a lost track
        starts = np.repeat(lo - (np.cumsum(counts) - counts), counts)
        pair_tracks = track_index[starts + np.arange(counts.sum())]
        pair_labels = np.repeat(member_labels, counts)
        # per label: its member nodes that belong to any remembered cluster
        known = np.bincount(member_labels[counts > 0], minlength=n_labels)
        keys, shared = np.unique(pair_labels * len(self._tracks) + pair_tracks,
                                 return_counts=True)
        labels, tracks = np.divmod(keys, len(self._tracks))
        candidates = sorted(
            zip(shared.tolist(), labels.tolist(), tracks.tolist(), strict=True),
            key=lambda c: (-c[0], -self._tracks[c[2]].last_seen, self._tracks[c[2]].track_id))
        taken_labels: set[int] = set()
        taken_tracks: set[int] = set()
        matches = []
        for count, label, track in candidates:
            if label in taken_labels or track in taken_tracks:
                continue
            if count < self.min_overlap * known[label]:
                continue
            taken_labels.add(label)
            taken_tracks.add(track)
            matches.append((label, self._tracks[track]))
        return matches
