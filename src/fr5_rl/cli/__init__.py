"""Command-line entry points (``scripts/*.py`` call these ``main`` functions).

Each module parses arguments and hands off to library code; errors in files or configuration
become one line on stderr and exit status 2. Nothing imports these modules but the scripts.
"""
import argparse
import sys
from typing import List, Optional

from ..help_text import HelpFormatter, plain


def script_args(argv: Optional[List[str]]) -> List[str]:
    """``argv``, or the command line without the ``__name:=`` / ``__log:=`` arguments roslaunch adds."""
    return argv if argv is not None else [a for a in sys.argv[1:] if not a.startswith("__")]


def fail(program: str, error: BaseException) -> int:
    """Print ``error`` as one line naming ``program``; the exit status for a refused input."""
    print(f"{program}: {error}", file=sys.stderr)
    return 2


def parser_from_doc(program: str, doc: str) -> argparse.ArgumentParser:
    """An argument parser whose description is ``doc``'s first paragraph and whose epilog is the
    rest (examples keep their layout)."""
    return argparse.ArgumentParser(prog=program, description=plain(doc.split("\n\n")[0]),
                                   epilog=plain(doc.split("\n\n", 1)[1]) if "\n\n" in doc else None,
                                   formatter_class=HelpFormatter)
