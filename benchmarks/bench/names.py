"""Names read from a results database (agents above all), as tables and messages show them.

A third-party agent may be named anything its ``module:Class`` or ``--agent-opt`` allows, so a
name is text to escape in every table format, never markup: :func:`md_cell` for Markdown
(``table_I.md``, ``rmm-bench compare``), :func:`md_cells` to read such a row back (the results
page lays out the Markdown table), :func:`tex_cell` for LaTeX (``table_I.tex``); CSV is written
with the :mod:`csv` module (or pandas), which quotes, and HTML with :func:`html.escape`.
:func:`did_you_mean` is the hint under an agent name that is not stored.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Iterable

__all__ = ["did_you_mean", "md_cell", "md_cells", "tex_cell"]

#: Markdown: the backslash first (so that the escapes added after it stay escapes), then the
#: cell separator, a code span's and raw HTML's openers and an entity's; GitHub's Markdown
#: shows each ``\X`` as ``X``
_MD_SPECIAL = re.compile(r"([\\|`<&])")
_NEWLINE = re.compile(r"\r\n|\r|\n")
#: a row of a Markdown table: cells split at the pipes no backslash escapes
_MD_SPLIT = re.compile(r"(?<!\\)((?:\\\\)*)\|")
_MD_UNESCAPE = re.compile(r"\\([\\|`<&])|<br>")
_TEX = {
    "\\": r"\textbackslash{}",
    "&": r"\&",
    "%": r"\%",
    "$": r"\$",
    "#": r"\#",
    "_": r"\_",
    "{": r"\{",
    "}": r"\}",
    "~": r"\textasciitilde{}",
    "^": r"\textasciicircum{}",
    "|": r"\textbar{}",  # the font's | < > are other glyphs outside math
    "<": r"\textless{}",
    ">": r"\textgreater{}",
}
_TEX_SPECIAL = re.compile("|".join(re.escape(c) for c in _TEX))


def md_cell(text: object) -> str:
    """``text`` as one cell of a Markdown table: ``\\``, ``|``, backticks, ``<`` and ``&``
    backslash-escaped, a line break written ``<br>`` (one line per row)."""
    escaped = _MD_SPECIAL.sub(r"\\\1", str(text))
    return _NEWLINE.sub("<br>", escaped)


def md_cells(line: str) -> list[str]:
    """The cells of one Markdown table row as :func:`md_cell` wrote them, unescaped again."""
    inner = line.strip()
    inner = inner[1:] if inner.startswith("|") else inner
    inner = inner[:-1] if inner.endswith("|") and not _escaped_end(inner) else inner
    cells = _MD_SPLIT.sub(lambda m: m.group(1) + "\0", inner).split("\0")
    return [_MD_UNESCAPE.sub(lambda m: m.group(1) or "\n", c.strip()) for c in cells]


def _escaped_end(text: str) -> bool:
    """Whether the ``|`` that ends ``text`` is escaped (an odd number of backslashes before it)."""
    body = text[:-1]
    return (len(body) - len(body.rstrip("\\"))) % 2 == 1


def tex_cell(text: object) -> str:
    """``text`` as one cell of a LaTeX tabular: its special characters escaped, line breaks as spaces."""
    return _NEWLINE.sub(" ", _TEX_SPECIAL.sub(lambda m: _TEX[m.group(0)], str(text)))


def did_you_mean(name: str, choices: Iterable[str]) -> str:
    """``" (did you mean 'x'?)"`` for the choice nearest ``name`` (as an env id typo gets), else ``""``."""
    near = difflib.get_close_matches(name, list(choices), n=1)
    return f" (did you mean {near[0]!r}?)" if near else ""
