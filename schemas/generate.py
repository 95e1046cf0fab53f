"""Regenerate the checked-in Python bindings from ``schemas/*.proto``.

Usage: ``python -m gngdt.schemas.generate [--out DIR]``. Runs protoc from grpcio-tools, so nothing
beyond the test dependencies is needed. The bindings are checked in so that users need no protoc;
``tests/unit/test_schemas.py`` fails when they drift from the .proto files.
"""

from __future__ import annotations

import argparse
import logging
import sys
from importlib import resources
from pathlib import Path

SCHEMA_DIR = Path(__file__).resolve().parent
PROTO_FILES = ("gngdt.proto",)

logger = logging.getLogger(__name__)


def generate(out_dir: Path = SCHEMA_DIR) -> list[Path]:
    """Run protoc on ``PROTO_FILES``; returns the generated ``*_pb2.py`` and ``.pyi`` paths."""
    from grpc_tools import protoc  # heavy and only in the test extra: import on use

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    well_known = resources.files("grpc_tools") / "_proto"
    arguments = [
        "protoc",
        f"--proto_path={SCHEMA_DIR}",
        f"--proto_path={well_known}",
        f"--python_out={out_dir}",
        f"--pyi_out={out_dir}",
        *(str(SCHEMA_DIR / name) for name in PROTO_FILES),
    ]
    status = protoc.main(arguments)
    if status != 0:
        raise RuntimeError(f"protoc failed with status {status}: {' '.join(arguments)}")
    generated = []
    for name in PROTO_FILES:
        stem = Path(name).stem
        generated += [out_dir / f"{stem}_pb2.py", out_dir / f"{stem}_pb2.pyi"]
    return generated


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=SCHEMA_DIR, help="output directory")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    for path in generate(args.out):
        logger.info("wrote %s", path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
