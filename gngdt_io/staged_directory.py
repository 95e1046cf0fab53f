"""An output folder that appears whole or not at all.

Everything is written into a hidden staging folder beside the target (same file system), which
is renamed to the target when the work succeeds. On any failure (an exception, Ctrl-C) the
staging folder is deleted and the target is left exactly as it was: absent, or its old contents.
An existing non-empty target is refused up front unless ``overwrite``; then it is replaced only
after the new folder is complete.
"""

from __future__ import annotations

import logging
import os
import secrets
import shutil
from pathlib import Path
from types import TracebackType

logger = logging.getLogger(__name__)


class StagedDirectory:
    """``with StagedDirectory(target) as staging: write into staging`` (see the module doc)."""

    def __init__(self, target: str | Path, overwrite: bool = False) -> None:
        self.target = Path(target)
        self.overwrite = overwrite
        if self.target.exists() and not self.target.is_dir():
            raise ValueError(f"{self.target}: exists and is not a folder")
        if self._target_has_files() and not overwrite:
            raise ValueError(f"{self.target}: folder exists and is not empty (choose another, "
                             "or --overwrite to replace it when the new one is complete)")
        self.staging: Path | None = None

    def _target_has_files(self) -> bool:
        return self.target.is_dir() and any(self.target.iterdir())

    def __enter__(self) -> Path:
        parent = self.target.parent
        parent.mkdir(parents=True, exist_ok=True)
        self.staging = _sibling(self.target, "partial")
        self.staging.mkdir()
        return self.staging

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 traceback: TracebackType | None) -> None:
        assert self.staging is not None
        if kind is not None:
            shutil.rmtree(self.staging, ignore_errors=True)
            logger.info("%s: nothing written (the run failed)", self.target)
            return
        try:
            self._commit()
        except BaseException:
            shutil.rmtree(self.staging, ignore_errors=True)
            raise

    def _commit(self) -> None:
        assert self.staging is not None
        if not self.target.exists():
            os.rename(self.staging, self.target)
            return
        if not self._target_has_files():
            self.target.rmdir()
            os.rename(self.staging, self.target)
            return
        old = _sibling(self.target, "old")
        os.rename(self.target, old)
        os.rename(self.staging, self.target)
        shutil.rmtree(old, ignore_errors=True)


def _sibling(target: Path, kind: str) -> Path:
    """A fresh hidden name beside ``target``: ``.<name>.<kind>-<pid>-<random>``."""
    return target.parent / f".{target.name}.{kind}-{os.getpid()}-{secrets.token_hex(4)}"
