"""MCAP recordings: reading (`reader`, `decoding`, `frame_assembly`), their bounds
(`limits`), poses from /tf (`poses`) and writing (`writer`)."""
