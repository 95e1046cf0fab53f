"""First contact: every command and sub-subcommand explains itself in --help."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import pytest

from gngdt.services.cli import build_parser, leaf_parsers

REPO_ROOT = Path(__file__).resolve().parents[2]


def _commands() -> list[tuple[str, argparse.ArgumentParser]]:
    """("gngdt <command> [<sub-command>]", its parser) for every command that takes options."""
    found = []
    for action in build_parser()._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                for leaf in leaf_parsers(sub):
                    found.append((leaf.prog, leaf))
    return found


COMMANDS = _commands()


def test_every_command_is_checked() -> None:
    progs = {prog for prog, _ in COMMANDS}
    assert {"gngdt record synth", "gngdt record images", "gngdt eval paper",
            "gngdt eval recording", "gngdt eval rrd", "gngdt run", "gngdt log",
            "gngdt segment", "gngdt eval segmentation"} <= progs


@pytest.mark.parametrize(("prog", "parser"), COMMANDS, ids=[prog for prog, _ in COMMANDS])
def test_help_has_a_description_examples_and_explains_every_option(
    prog: str, parser: argparse.ArgumentParser
) -> None:
    text = parser.format_help()
    assert parser.description and len(parser.description) > 20, f"{prog}: no description"
    assert parser.epilog and "examples:" in parser.epilog, f"{prog}: no examples"
    assert prog in parser.epilog, f"{prog}: the examples do not show the command itself"
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        name = "/".join(action.option_strings) or action.dest
        assert action.help and action.help != argparse.SUPPRESS, f"{prog} {name}: no help"
    assert not re.search(r"\(default[^()]*\)\s*\(default", text), f"{prog}: doubled default"
    assert "--log-level" in text


def test_record_synth_help_lists_the_scenes() -> None:
    from gngdt.io.synth.render import SCENES

    text = dict(COMMANDS)["gngdt record synth"].format_help()
    for scene in SCENES:
        assert scene in text


def test_the_readme_promises_what_the_help_does() -> None:
    assert "Every command has `--help` with examples" in (REPO_ROOT / "README.md").read_text()


def test_sub_subcommands_accept_the_common_options() -> None:
    args = build_parser().parse_args(["record", "synth", "--scene", "data2", "--frames", "1",
                                      "--out", "x.mcap", "--log-level", "DEBUG"])
    assert args.log_level == "DEBUG"


def test_descriptions_are_whole_sentences_and_the_version_is_the_packages(capsys) -> None:
    """A description is the module's first paragraph, never cut mid-sentence; --version says
    the installed package's version."""
    from importlib.metadata import version

    for prog, parser in COMMANDS:
        assert parser.description.rstrip().endswith((".", ")")), f"{prog}: {parser.description}"
    with pytest.raises(SystemExit) as exit_info:
        build_parser().parse_args(["--version"])
    assert exit_info.value.code == 0
    assert capsys.readouterr().out.strip() == f"gngdt {version('gngdt')}"
