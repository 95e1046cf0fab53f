"""Evaluation: the paper's tables, recordings scored against references, logged runs read back,
segmentation on labelled real frames. Needs the ``eval`` extra (scikit-learn, matplotlib).

Modules: ``paper`` (Tables 2-4, Figure 10), ``recording_eval`` (a recording replayed through the
learner's own per-frame policy), ``rrd`` (metrics of a logged run), ``segmentation`` (segments on
labelled real frames, scored by ``segment_scores``, beside the Open3D peer of ``open3d_peer``),
``baselines`` (k-means, voxel grid, DBSCAN), ``report`` (Markdown + JSON writing), ``plots``
(matplotlib PNGs), ``progress`` (a one-line progress counter), ``cli`` (``gngdt eval``).
"""
