"""MkDocs hooks (mkdocs.yml `hooks:`): the pages made from the repository at each build.

- reference/cli.md: every command and option, walked from the argument parser (cli_reference.py);
- reference/registers.md: protocol/PROTOCOL.md, which tools/gen_protocol.py generates from
  protocol/registers.toml;
- reference/firmware.md: firmware/README.md, the firmware's layout and porting guide;
- howto/messages.md: its marker `<!-- generated: messages -->` replaced by the errors and notes
  collected from the source (messages.py);
- the equations (pymdownx.arithmatex's \\( \\) and \\[ \\]) turned into MathML at build time, which
  browsers draw themselves: the pages need no script and no network to show them;
- img/generated/*.png: the tutorials' pictures that tools/docs/figures.py made into
  build/docs/figures by running the tutorials' steps; a picture not made yet (`make docs-check`
  builds without running them) is a small placeholder that says so.
"""
import html
import re
import sys
from pathlib import Path

from latex2mathml.converter import convert as tex_to_mathml

from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[2]
FIGURES = ROOT / "build" / "docs" / "figures"
for path in (ROOT / "host", ROOT / "tools" / "docs"):
    if str(path) not in sys.path:
        sys.path.insert(0, str(path))

import cli_reference  # noqa: E402  (after the path above)
import figures  # noqa: E402
import messages  # noqa: E402


def _with_source(text, source):
    return f"<!-- made at each `make docs` from {source}: edit that, not this page -->\n{text}"


def _generated_pages():
    protocol = (ROOT / "protocol" / "PROTOCOL.md").read_text(encoding="utf-8")
    firmware = (ROOT / "firmware" / "README.md").read_text(encoding="utf-8")
    return {
        "reference/cli.md": _with_source(cli_reference.page(), "the argument parser (tools/docs/cli_reference.py)"),
        "reference/registers.md": _with_source(protocol, "protocol/registers.toml (tools/gen_protocol.py)"),
        "reference/firmware.md": _with_source(firmware.replace("# facette firmware", "# Firmware and porting", 1),
                                              "firmware/README.md"),
    }


MATH = re.compile(r'<(span|div) class="arithmatex">\\[\(\[](.*?)\\[\)\]]</\1>', re.S)


def _mathml(match):
    display = "block" if match.group(1) == "div" else "inline"
    return tex_to_mathml(html.unescape(match.group(2)), display=display)


def on_page_content(content, page, config, files):
    return MATH.sub(_mathml, content)


MESSAGES_MARK = "<!-- generated: messages -->"


def on_page_markdown(markdown, page, config, files):
    if page.file.src_uri == "howto/messages.md":
        return markdown.replace(MESSAGES_MARK, messages.page_section())
    return markdown


def on_files(files, config):
    for uri, text in _generated_pages().items():
        files.append(File.generated(config, uri, content=text))
    for name in figures.NAMES:
        made = FIGURES / name
        uri = f"img/generated/{name}"
        if made.exists():
            files.append(File.generated(config, uri, abs_src_path=str(made)))
        else:
            files.append(File.generated(config, uri, content=figures.placeholder_png(name)))
    return files
