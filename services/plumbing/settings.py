"""A service's options declared once, and handed from `gngdt run` to the service.

Each service declares the options that say what it does (how it learns, what it reads, what it
logs) as an `OptionGroup`: its own command line has them, `gngdt run` adds the same group to
its parser, and hands the parsed values to the service in a settings file (``--settings FILE``,
JSON) that the service reads back into its own namespace through the same declaration. An option
added to a group is therefore an option of `gngdt run` too, and reaches the service, without
editing `gngdt run`. Values a run decides for a service (its camera name, its point cap under
``--track``) go into the same file.
"""

from __future__ import annotations

import argparse
import json
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

#: what a settings file holds at most (a real one is under 4 kB)
MAX_SETTINGS_BYTES = 1 << 20

Declare = Callable[[Any], None]  # adds arguments to a parser or an argument group


@dataclass(frozen=True)
class OptionGroup:
    """Options of one service: ``declare`` adds them to a parser or an argument group."""

    title: str
    declare: Declare

    def add_to(self, parser: argparse.ArgumentParser) -> None:
        """The options, as an argument group of ``parser`` titled ``title``."""
        self.declare(parser.add_argument_group(self.title))

    def actions(self) -> dict[str, argparse.Action]:
        """The declared options by destination."""
        parser = argparse.ArgumentParser(add_help=False)
        self.declare(parser)
        return {action.dest: action for action in parser._actions}

    def values(self, args: argparse.Namespace) -> dict[str, Any]:
        """The group's values in ``args`` (as parsed by a parser the group was added to)."""
        return {dest: getattr(args, dest) for dest in self.actions() if hasattr(args, dest)}

    def apply(self, values: dict[str, Any], args: argparse.Namespace) -> None:
        """Set the group's ``values`` (as read from a settings file) on ``args``; a value read
        as text goes through its option's type again (a path becomes a `Path`). ValueError for
        a value the group does not declare."""
        actions = self.actions()
        unknown = sorted(set(values) - set(actions))
        if unknown:
            raise ValueError(f"settings for {self.title!r}: unknown option(s) {unknown}")
        for dest, value in values.items():
            kind = actions[dest].type
            if isinstance(value, str) and callable(kind):
                value = kind(value)
            setattr(args, dest, value)


def add_settings_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--settings", type=Path, metavar="FILE",
                        help="read this service's options from FILE (JSON, as `gngdt run` writes "
                        "it for each service it starts); they take the place of the same "
                        "options on the command line")


def write_settings(path: Path, values: dict[str, Any]) -> Path:
    """``values`` (option destination -> value) into ``path``, readable by its owner only."""
    text = json.dumps(values, indent=2, sort_keys=True,
                      default=lambda value: str(value) if isinstance(value, Path) else value)
    descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(descriptor, "w") as file:
        file.write(text)
    return path


def read_settings(path: Path) -> dict[str, Any]:
    """A settings file's values; ValueError naming the file when it is not one."""
    try:
        if path.stat().st_size > MAX_SETTINGS_BYTES:
            raise ValueError(f"--settings {path}: larger than {MAX_SETTINGS_BYTES} bytes")
        values = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise ValueError(f"--settings {path}: {error}") from error
    if not isinstance(values, dict):
        raise ValueError(f"--settings {path}: not a JSON object")
    return values


def apply_settings(args: argparse.Namespace, groups: list[OptionGroup]) -> None:
    """Read ``args.settings`` (if given) into ``args``: each value through the group declaring
    it; ValueError for a file that is not a settings file of these groups."""
    path = getattr(args, "settings", None)
    if path is None:
        return
    values = read_settings(path)
    for group in groups:
        declared = group.actions()
        group.apply({dest: values.pop(dest) for dest in list(values) if dest in declared}, args)
    if values:
        raise ValueError(f"--settings {path}: unknown option(s) {sorted(values)}")
