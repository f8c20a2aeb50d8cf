"""Module docstrings as command-line help: the reStructuredText markup that Sphinx reads
(````code````, ``:class:`~a.B```, ```x```) is noise in a terminal."""
from __future__ import annotations

import argparse
import re

_ROLE = re.compile(r":[a-z]+:`~?(?:[\w.]+\.)?([^`<]+?)`")
_LITERAL = re.compile(r"``([^`]+)``|`([^`]+)`")


def plain(text: str) -> str:
    """``text`` without the markup: roles keep their last name, literals their text."""
    text = _ROLE.sub(r"\1", text)
    return _LITERAL.sub(lambda match: match.group(1) or match.group(2), text)


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """The description's and epilog's lines as written; each option's default shown, unless its
    help already says it, or it has none worth saying (a switch, an unset value)."""

    @staticmethod
    def _says_nothing_of_its_default(action: argparse.Action) -> bool:
        text = action.help or ""
        return bool(action.option_strings) and "default" not in text.lower() and "(" not in text[-12:] \
            and not (action.default is None or action.default is False or action.default is argparse.SUPPRESS
                     or action.default == "") and text != argparse.SUPPRESS

    def add_argument(self, action: argparse.Action) -> None:
        if action.help is None and self._says_nothing_of_its_default(action):
            action.help = ""  # argparse lists no help line for None; the default still deserves one
        super().add_argument(action)

    def _format_action(self, action: argparse.Action) -> str:
        if action.help == "" and self._says_nothing_of_its_default(action):
            action = argparse.Action(action.option_strings, action.dest, nargs=action.nargs, default=action.default,
                                     choices=action.choices, metavar=action.metavar,
                                     help="(default: %(default)s)")
        return super()._format_action(action)

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if not self._says_nothing_of_its_default(action):
            return text
        return f"{text} (default: %(default)s)" if text else "(default: %(default)s)"
