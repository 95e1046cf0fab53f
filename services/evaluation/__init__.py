"""Evaluation: the paper's tables, recordings scored against references, logged runs read back.

Modules: ``paper`` (Tables 2-4, Figure 10), ``recording`` (offline replay of an MCAP recording),
``rrd`` (metrics of a logged run), ``segmentation`` (segments on labelled real frames, scored by
``segment_scores``, beside the Open3D peer of ``open3d_peer``), ``references`` (k-means, voxel
grid, DBSCAN), ``report`` (Markdown + JSON writing), ``plots`` (matplotlib PNGs), ``progress``
(a one-line progress counter), ``cli`` (the ``gngdt eval`` subcommand).
"""
