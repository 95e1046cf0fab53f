"""The per-frame policies: how a stream of frames becomes a network. The
services' learner (`frame_learner`), `gngdt segment`'s (`frame_segmenter`), the stream
learner under both (`stream_learner`), a live learner's time budget (`frame_budget`) and the
kernels' compilation before the first frame (`warm_up`)."""
