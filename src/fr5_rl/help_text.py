"""Module docstrings as command-line help: the reStructuredText markup that Sphinx reads
(````code````, ``:class:`~a.B```, ```x```) is noise in a terminal."""
from __future__ import annotations

import re

_ROLE = re.compile(r":[a-z]+:`~?(?:[\w.]+\.)?([^`<]+?)`")
_LITERAL = re.compile(r"``([^`]+)``|`([^`]+)`")


def plain(text: str) -> str:
    """``text`` without the markup: roles keep their last name, literals their text."""
    text = _ROLE.sub(r"\1", text)
    return _LITERAL.sub(lambda match: match.group(1) or match.group(2), text)
