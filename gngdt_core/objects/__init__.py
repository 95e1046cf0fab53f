"""Objects from a learned network: one per cluster or segment, summarised
(`object_set`), with an id that persists from frame to frame (`ids`)."""
