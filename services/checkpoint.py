"""Learner checkpoints: a model state plus metadata in one ``.npz``, written atomically.

Layout: every state array under ``state/<name>``; ``metadata`` is a JSON string (0-d unicode
array) holding the caller's metadata and ``state_sha256``, a digest of the state arrays (names,
dtypes, shapes and bytes) that catches truncated or altered files. Loading never unpickles.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

_STATE_PREFIX = "state/"
_METADATA_KEY = "metadata"
FORMAT_VERSION = 1


class CheckpointError(ValueError):
    """A checkpoint file cannot be used; the message names the file and the reason."""


def state_digest(state: dict[str, np.ndarray]) -> str:
    """sha256 hex digest of the arrays' names, dtypes, shapes and contents."""
    digest = hashlib.sha256()
    for name in sorted(state):
        array = np.ascontiguousarray(state[name])
        digest.update(f"{name}|{array.dtype.str}|{array.shape}|".encode())
        digest.update(array.tobytes())
    return digest.hexdigest()


def save_checkpoint(
    path: Path, state: dict[str, np.ndarray], metadata: dict[str, Any] | None = None
) -> None:
    """Write ``state`` (numpy arrays only) and JSON-able ``metadata`` to ``path`` atomically."""
    path = Path(path)
    arrays = {f"{_STATE_PREFIX}{name}": np.asarray(value) for name, value in state.items()}
    for key, array in arrays.items():
        if array.dtype == object:
            raise ValueError(f"checkpoint state {key!r} is an object array; numeric arrays only")
    full_metadata = {
        **(metadata or {}),
        "format_version": FORMAT_VERSION,
        "state_sha256": state_digest(state),
    }
    arrays[_METADATA_KEY] = np.array(json.dumps(full_metadata))
    path.parent.mkdir(parents=True, exist_ok=True)
    descriptor, temporary = tempfile.mkstemp(
        prefix=f".{path.name}.", suffix=".tmp", dir=path.parent
    )
    try:
        with os.fdopen(descriptor, "wb") as file:
            np.savez(file, **arrays)
            file.flush()
            os.fsync(file.fileno())
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


def load_checkpoint(path: Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """``(state, metadata)`` of a checkpoint; ``CheckpointError`` if it is corrupt or foreign."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as archive:
            if _METADATA_KEY not in archive.files:
                raise CheckpointError(f"checkpoint {path}: no metadata; not a gngdt checkpoint")
            metadata = json.loads(str(archive[_METADATA_KEY]))
            state = {
                key[len(_STATE_PREFIX):]: archive[key]
                for key in archive.files
                if key.startswith(_STATE_PREFIX)
            }
    except CheckpointError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile, EOFError, KeyError) as error:
        raise CheckpointError(f"checkpoint {path}: unreadable ({error})") from error
    if not isinstance(metadata, dict) or "state_sha256" not in metadata:
        raise CheckpointError(f"checkpoint {path}: metadata has no state_sha256")
    if metadata["state_sha256"] != state_digest(state):
        raise CheckpointError(f"checkpoint {path}: content does not match its sha256")
    return state, metadata
