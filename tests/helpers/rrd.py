"""What a rerun recording (.rrd) holds, read back with rerun's own reader."""

from __future__ import annotations

from pathlib import Path

#: what `gngdt run` must write (docs/contracts.md "Rerun"), for the default camera
DESIGN_ENTITIES = {
    "/world/camera",
    "/world/camera/image/rgb",
    "/world/camera/image/depth",
    "/world/points",
    "/world/gng/nodes",
    "/world/gng/edges/pos",
    "/world/gng/edges/col",
    "/world/gng/edges/nor",
    "/world/gng/edges/col\\+nor",  # rerun escapes "+" in entity paths
    "/metrics/nodes",
    "/metrics/steps_per_second",
    "/metrics/latency_ms",
    "/metrics/quantization_error/pos",
    "/metrics/quantization_error/col",
    "/metrics/clusters/col",
    "/metrics/clusters/nor",
}


def rrd_entities_and_scalars(path: Path) -> tuple[set[str], dict[str, list[tuple[int, float]]]]:
    """Entity paths in an .rrd, and every ``metrics/...`` scalar as (frame, value) pairs."""
    from rerun.chunk import RrdReader

    store = RrdReader(path).stream().collect()
    entities: set[str] = set()
    scalars: dict[str, list[tuple[int, float]]] = {}
    for chunk in store.stream():
        entities.add(chunk.entity_path)
        if chunk.entity_path.startswith("/metrics/"):
            batch = chunk.to_record_batch()
            frames = batch.column("frame").to_pylist()
            values = batch.column("Scalars:scalars").to_pylist()
            scalars.setdefault(chunk.entity_path, []).extend(
                (frame, value[0]) for frame, value in zip(frames, values, strict=True))
    return entities, scalars


def rrd_rows(path: Path) -> dict[str, int]:
    """Rows per entity path of an .rrd (with or without its footer)."""
    import warnings

    from rerun.chunk import RrdReader

    rows: dict[str, int] = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "no footer" after a kill -9: expected here
        store = RrdReader(path).stream().collect()
    for chunk in store.stream():
        rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    return rows
