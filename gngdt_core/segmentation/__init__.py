"""Segments a robot can use, from a learned network: the procedure
(`network`), support surfaces and roles (`supports`), segments joined across gaps of missing
depth (`gaps`)."""
