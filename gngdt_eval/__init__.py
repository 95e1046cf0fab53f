"""Evaluation: the paper's tables, recordings scored against references, logged runs read back,
segmentation on labelled real frames. Needs the ``eval`` extra (scikit-learn, matplotlib).

Modules: ``paper`` (the simulation's trials: Tables 2-4, Figures 8-11) with ``paper_common``
(the published numbers, ``PaperSettings``), ``paper_methods`` (the three methods as the paper
runs them), ``paper_summary`` (tables and claims), ``paper_rgbd`` (Tables 5-6 on real frames)
and ``paper_report``; ``recording_eval`` (a recording replayed through the learner's own
per-frame policy) and ``recording_report`` (its Markdown and plots), ``rrd`` (metrics of a
logged run), ``segmentation`` (segments on labelled real frames, scored by ``segment_scores``,
beside the Open3D peer of ``open3d_peer``), ``baselines`` (k-means, voxel grid, DBSCAN),
``report`` (Markdown + JSON writing), ``plots`` (matplotlib PNGs), ``progress`` (a one-line
progress counter), ``cli`` (``gngdt eval``).
"""
