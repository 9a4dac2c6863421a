"""The generated reference pages (tools/docs): every command and option of the argument parser is
on the command reference, and the messages page holds the errors and hints the source raises."""
import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools" / "docs"))

import cli_reference  # noqa: E402  (tools/docs, on the path above)
import messages  # noqa: E402


def test_every_command_and_option_is_on_the_reference_page():
    from facette.cli.main import COMMANDS

    page = cli_reference.page()
    for name in COMMANDS:
        assert f"## facette {name}" in page
        parser = cli_reference.command_parser(name)
        for action in parser._actions:
            if isinstance(action, argparse._HelpAction) or action.help == argparse.SUPPRESS:
                continue
            shown = action.option_strings or [action.metavar or action.dest]
            assert all(f"`{flag}" in page for flag in shown), (name, shown)


def test_an_option_added_to_a_command_appears_without_editing_the_page(monkeypatch):
    """The page is walked from the parser, not typed: a new option shows at the next build."""
    import facette.cli._relight as relight

    original = relight.register

    def register(sub):
        p = original(sub)
        p.add_argument("--brand-new", default=3, help="an option added later (default %(default)s)")
        return p

    monkeypatch.setattr(relight, "register", register)
    page = cli_reference.page()
    assert "| `--brand-new BRAND_NEW` | `3` |  | an option added later (default 3) |" in page


def test_messages_are_collected_with_their_hints_and_notes(tmp_path):
    (tmp_path / "errors.py").write_text("class FacetteError(Exception): pass\n"
                                        "class BadInputError(FacetteError, ValueError): pass\n")
    (tmp_path / "io").mkdir()
    (tmp_path / "io" / "reader.py").write_text(
        "from ..errors import BadInputError\n"
        "class FolderError(BadInputError): pass\n"
        "def read(path, notes):\n"
        "    notes.append(f'read {path} as sRGB')\n"
        "    if not path:\n"
        "        raise FolderError(f'no photographs in {path}', hint='give a folder of JPEGs')\n"
        "    raise ValueError('not collected: not a facette error kind')\n")
    found = messages.collect(tmp_path)
    assert found["io"]["errors"] == [("FolderError", "no photographs in {...}", "give a folder of JPEGs")]
    assert found["io"]["notes"] == ["read {...} as sRGB"]


def test_messages_page_covers_the_package():
    found = messages.collect()
    errors = [e for area in found.values() for e in area["errors"]]
    assert len(errors) > 100 and sum(1 for _, _, hint in errors if hint) > 30
    assert {"cli", "pipeline", "scan"} <= {area for area, got in found.items() if got["errors"]}
    section = messages.page_section()
    assert "### the command line" in section and "what to do" in section


def test_run_time_parts_of_a_message_are_shown_as_placeholders():
    import ast

    node = ast.parse('f"light {i} of {path.name} is dark" + " (see --help)"', mode="eval").body
    assert messages.text_of(node) == "light {...} of {...} is dark (see --help)"
