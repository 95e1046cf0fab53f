"""The camera as the algorithm sees it: pinhole intrinsics and rigid transforms
(`geometry`), depth images (`depth`), and what the sensor saw in one batch (`view`)."""
