"""The growing neural gas itself: GNG-DT and the paper's baselines (`model`,
`baselines`), their state (`state`), input checks and sampling order (`sampling`), read-only
queries (`queries`), rehearsal (`rehearsal`) and the node budget that grows with the surface
seen (`coverage`)."""
