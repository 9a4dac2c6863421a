"""The command reference page, walked from the argument parser `facette.cli.main` builds.

Every subcommand of `facette.cli.main.COMMANDS` is registered on a parser of its own and each of
its arguments written out (flags, metavar, default, choices, help), so an option added to a
command's `register()` appears here at the next `make docs` with nothing typed by hand.
The benchmarks (`facette bench NAME`) are listed from `facette.cli._bench.available()`.
"""
import argparse
import importlib
import textwrap


def _cell(text):
    return " ".join(str(text).split()).replace("|", "\\|")


def _help(parser, action):
    if not action.help or action.help == argparse.SUPPRESS:
        return ""
    try:
        return parser._get_formatter()._expand_help(action)   # %(default)s and friends
    except (KeyError, TypeError, ValueError):
        return action.help


def _flags(action):
    if action.option_strings:
        metavar = ""
        if action.nargs != 0:
            metavar = action.metavar or action.dest.upper()
            metavar = " " + (" ".join(metavar) if isinstance(metavar, tuple) else metavar)
        return ", ".join(f"`{s}{metavar}`" for s in action.option_strings)
    return f"`{action.metavar or action.dest}`"


def _default(action):
    if action.nargs == 0 or action.default in (None, argparse.SUPPRESS) or action.required:
        return ""
    return f"`{action.default!r}`" if not isinstance(action.default, str) else f"`{action.default}`"


def _choices(action):
    if not action.choices or isinstance(action, argparse._SubParsersAction):
        return ""
    return ", ".join(f"`{c}`" for c in action.choices)


def arguments_table(parser):
    """Markdown table of one parser's arguments (positional first, as the usage line has them)."""
    rows = ["| argument | default | choices | what it does |", "| --- | --- | --- | --- |"]
    actions = [a for a in parser._actions if not isinstance(a, argparse._HelpAction)]
    actions.sort(key=lambda a: bool(a.option_strings))
    for action in actions:
        if action.help == argparse.SUPPRESS or isinstance(action, argparse._SubParsersAction):
            continue
        required = " (required)" if action.option_strings and action.required else ""
        rows.append(f"| {_flags(action)}{required} | {_cell(_default(action))} | {_cell(_choices(action))} "
                    f"| {_cell(_help(parser, action))} |")
    return "\n".join(rows)


def _usage(parser):
    usage = parser.format_usage().strip()
    usage = usage[len("usage: "):] if usage.startswith("usage: ") else usage
    return "```text\n" + "\n".join(textwrap.wrap(" ".join(usage.split()), 96, subsequent_indent="    ")) + "\n```"


def command_parser(name):
    """The full parser of `facette NAME`, registered as the command line registers it."""
    return _registered(name)[0]


def _registered(name):
    """(parser of `facette NAME`, its one-line help as the command registers it)."""
    from facette.cli.main import COMMANDS, _Parser

    root = _Parser(prog="facette")
    sub = root.add_subparsers(dest="command", parser_class=_Parser)
    parser = importlib.import_module(COMMANDS[name][0]).register(sub)
    helps = [a.help for a in sub._choices_actions if a.dest == name and a.help]
    return parser, (helps[0] if helps else COMMANDS[name][1])


def _description(parser):
    text = (parser.description or "").strip()
    if not text:
        return ""
    return "```text\n" + textwrap.dedent(text) + "\n```" if "\n" in text else text


def page():
    from facette.cli._bench import available
    from facette.cli.main import COMMANDS

    out = ["# Command reference", "",
           "Every `facette` command and option, generated from the argument parser at each "
           "`make docs` (`tools/docs/cli_reference.py`). `facette COMMAND --help` prints the same.",
           "", "| command | what it does |", "| --- | --- |"]
    commands = {name: _registered(name) for name in COMMANDS}
    out += [f"| [`facette {name}`](#facette-{name}) | {_cell(help_text)} |"
            for name, (_, help_text) in commands.items()]
    out += ["", "Exit codes: 0 done, 1 a scan stopped or the device refused (run the same command again "
            "to resume), 2 bad input (nothing started), 3 the data cannot give the result asked for, "
            "70 a bug in facette, 130 interrupted ([messages and errors](../howto/messages.md))."]
    for name, (parser, help_text) in commands.items():
        out += ["", f"## facette {name}", "", _cell(help_text) + ".", "", _usage(parser)]
        desc = _description(parser)
        if desc and desc.strip() != help_text.strip():
            out += ["", desc]
        out += ["", arguments_table(parser)]
        if name == "bench":
            out += ["", "Benchmarks (`facette bench all` runs each and writes the "
                    "[benchmarks page](../benchmarks.md)): " + ", ".join(f"`{b}`" for b in available()) + "."]
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    print(page())
