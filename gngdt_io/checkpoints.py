"""Learner checkpoints: a model state plus metadata in one ``.npz``, written atomically.

Layout: every state array under ``state/<name>``; ``metadata`` is a JSON string (0-d unicode
array) holding the caller's metadata, ``format_version`` and ``sha256``, a digest of the state
arrays (names, dtypes, shapes and bytes) and of the rest of the metadata, which catches truncated
or corrupted files and edits that did not recompute it (an integrity check, not a signature:
whoever may write the file may rewrite the digest, so keep checkpoints where only the learner
writes). Loading is all or nothing: nothing is returned unless every check passes. It
never unpickles or evaluates anything, and refuses archives whose declared size is beyond
``MAX_CHECKPOINT_BYTES``, and arrays whose ``.npy`` header promises more data than the archive
holds, before reading them.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import tempfile
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

_STATE_PREFIX = "state/"
_METADATA_KEY = "metadata"
_DIGEST_KEY = "sha256"
FORMAT_VERSION = 2
#: largest uncompressed checkpoint accepted (a 1,000,000-node model is ~100 MB)
MAX_CHECKPOINT_BYTES = 2 * 1024**3
#: largest metadata JSON accepted (a real one is well under a kilobyte)
MAX_METADATA_BYTES = 1024**2


class CheckpointError(ValueError):
    """A checkpoint file cannot be used; the message names the file and the reason."""


def checkpoint_digest(state: dict[str, np.ndarray], metadata: dict[str, Any]) -> str:
    """sha256 hex digest of the arrays' names, dtypes, shapes and contents and of ``metadata``
    (canonical JSON, without the digest itself)."""
    digest = hashlib.sha256()
    for name in sorted(state):
        array = np.ascontiguousarray(state[name])
        digest.update(f"{name}|{array.dtype.str}|{array.shape}|".encode())
        digest.update(array.tobytes())
    signed = {key: value for key, value in metadata.items() if key != _DIGEST_KEY}
    digest.update(json.dumps(signed, sort_keys=True).encode())
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
    full_metadata = {**(metadata or {}), "format_version": FORMAT_VERSION}
    full_metadata[_DIGEST_KEY] = checkpoint_digest(state, full_metadata)
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
        _check_declared_size(path)
        with np.load(path, allow_pickle=False) as archive:
            if not isinstance(archive, np.lib.npyio.NpzFile):
                raise CheckpointError(f"checkpoint {path}: not an .npz archive")
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
    except RecursionError as error:  # JSON nested deeper than the interpreter recurses
        raise CheckpointError(f"checkpoint {path}: metadata nested too deeply") from error
    except (OSError, ValueError, zipfile.BadZipFile, EOFError, KeyError, MemoryError) as error:
        raise CheckpointError(f"checkpoint {path}: unreadable ({error})") from error
    if not isinstance(metadata, dict) or _DIGEST_KEY not in metadata:
        raise CheckpointError(f"checkpoint {path}: metadata has no {_DIGEST_KEY}")
    if metadata.get("format_version") != FORMAT_VERSION:
        raise CheckpointError(
            f"checkpoint {path}: format version {metadata.get('format_version')!r}, "
            f"this gngdt reads version {FORMAT_VERSION}"
        )
    if metadata[_DIGEST_KEY] != checkpoint_digest(state, metadata):
        raise CheckpointError(
            f"checkpoint {path}: content does not match its sha256 (torn or altered file)"
        )
    return state, metadata


def _check_declared_size(path: Path) -> None:
    """Refuse an archive that declares more than ``MAX_CHECKPOINT_BYTES`` (e.g. a zip bomb), or
    holds an array whose ``.npy`` header does not match the bytes stored for it."""
    if not path.is_file():
        raise CheckpointError(f"checkpoint {path}: no such file")
    if not zipfile.is_zipfile(path):
        raise CheckpointError(f"checkpoint {path}: not a zip (.npz) archive; torn or foreign file")
    with zipfile.ZipFile(path) as archive:
        members = archive.infolist()
        declared = sum(item.file_size for item in members)
        if declared > MAX_CHECKPOINT_BYTES:
            raise CheckpointError(
                f"checkpoint {path}: declares {declared} bytes, more than {MAX_CHECKPOINT_BYTES}"
            )
        for member in members:
            _check_npy_header(path, archive, member)


def _check_npy_header(path: Path, archive: zipfile.ZipFile, member: zipfile.ZipInfo) -> None:
    """The array's header (shape x itemsize) must account for exactly the member's bytes."""
    name = member.filename.removesuffix(".npy")
    try:
        with archive.open(member) as file:
            version = np.lib.format.read_magic(file)
            read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                           else np.lib.format.read_array_header_2_0)
            shape, _, dtype = read_header(file)
            header_bytes = file.tell()
    except (ValueError, OSError, zipfile.BadZipFile, EOFError) as error:
        raise CheckpointError(f"checkpoint {path}: array {name!r} has no valid header "
                              f"({error})") from error
    if dtype.hasobject:
        raise CheckpointError(f"checkpoint {path}: array {name!r} holds Python objects")
    data_bytes = math.prod(shape) * dtype.itemsize
    if data_bytes != member.file_size - header_bytes:
        raise CheckpointError(
            f"checkpoint {path}: array {name!r} declares {shape} {dtype} ({data_bytes} bytes) "
            f"but holds {member.file_size - header_bytes}")
    if name == _METADATA_KEY and data_bytes > MAX_METADATA_BYTES:
        raise CheckpointError(f"checkpoint {path}: metadata of {data_bytes} bytes is larger "
                              f"than {MAX_METADATA_BYTES}")


def remove_stale_temporaries(path: Path) -> list[Path]:
    """Delete the temporaries an interrupted :func:`save_checkpoint` of ``path`` left behind
    (``kill -9`` mid-write); call it while holding the :class:`CheckpointLock`."""
    path = Path(path)
    removed = []
    for temporary in path.parent.glob(f".{path.name}.*.tmp"):
        try:
            temporary.unlink()
        except OSError:
            continue
        removed.append(temporary)
    return removed


class CheckpointLock:
    """An exclusive lock on a checkpoint path, so that two learners never share one file.

    ``flock`` on ``.<name>.lock`` beside the checkpoint: released by the kernel when the holder
    exits, however it exits, so a killed learner never leaves a stale lock.
    """

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.lock_path = self.path.with_name(f".{self.path.name}.lock")
        self._file: Any = None

    def acquire(self) -> CheckpointLock:
        """Take the lock; ``CheckpointError`` naming the holder's pid when another has it, or
        the folder when it cannot be written (read-only, missing permissions)."""
        import fcntl

        try:
            self.lock_path.parent.mkdir(parents=True, exist_ok=True)
            file = open(self.lock_path, "a+")  # kept open while the lock is held
        except OSError as error:
            raise CheckpointError(
                f"checkpoint {self.path}: its folder cannot be written ({error.strerror or error});"
                " the learner saves its checkpoint there: give a --checkpoint in a writable "
                "folder") from error
        try:
            fcntl.flock(file.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            file.seek(0)
            holder = file.read().strip() or "?"
            file.close()
            raise CheckpointError(
                f"checkpoint {self.path} is in use by another learner (pid {holder}); "
                "give each learner its own --checkpoint") from None
        file.seek(0)
        file.truncate()
        file.write(f"{os.getpid()}\n")
        file.flush()
        self._file = file
        return self

    def release(self) -> None:
        if self._file is not None:
            self._file.close()  # closing the descriptor releases the flock
            self._file = None
