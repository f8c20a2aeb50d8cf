"""The previous release's code, for benches that compare old against new in the same run.

    from reference import reference_release, reference_tree, reference_environment
    tree = reference_tree(reference_release())      # an export of that commit, cached
    subprocess.run([sys.executable, str(tree / "scripts" / "train.py"), ...], env=reference_environment(tree))

The release is named in ``tools/bench/reference_release.yaml`` (a commit of this repository);
``--reference REV`` on a bench overrides it. The commit is exported with ``git archive`` (what a
``git worktree`` would check out, without touching this repository's worktree list) into the
user's cache, once per commit, and run with this checkout's interpreter and packages: only
``fr5_rl`` and its config, URDF and scripts are the old ones.

Imports only the standard library and PyYAML.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import tarfile
import tempfile
from pathlib import Path
from typing import Dict, Optional, Tuple

import yaml

REPO = Path(__file__).resolve().parents[2]
RELEASE_FILE = Path(__file__).resolve().parent / "reference_release.yaml"


class ReferenceUnavailable(RuntimeError):
    """The reference commit cannot be had here (no git, a shallow clone, an unknown revision)."""


def reference_release() -> str:
    """The commit named in reference_release.yaml (``release``)."""
    with open(RELEASE_FILE, encoding="utf-8") as handle:
        return str(yaml.safe_load(handle)["release"])


def resolve(revision: str) -> str:
    """The full commit id of ``revision`` in this repository.

    :raises ReferenceUnavailable: with what to do next.
    """
    try:
        result = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--verify", "--quiet", f"{revision}^{{commit}}"],
                                capture_output=True, text=True, check=False)
    except FileNotFoundError:
        raise ReferenceUnavailable("git is not installed: the old-against-new comparison needs it") from None
    if result.returncode != 0:
        raise ReferenceUnavailable(
            f"commit {revision} is not in this clone (a shallow clone?); `git fetch --unshallow` or pass "
            "--reference REV with a commit it has")
    return result.stdout.strip()


def cache_dir() -> Path:
    """Where exported trees are kept: ``$XDG_CACHE_HOME/fr5_rl/reference`` (default ``~/.cache``)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "fr5_rl" / "reference"


def reference_tree(revision: str) -> Path:
    """The files of ``revision``, exported once into :func:`cache_dir` (atomically: parallel
    benches may race) and reused.

    :raises ReferenceUnavailable: the commit is not in this clone.
    """
    commit = resolve(revision)
    tree = cache_dir() / commit[:12]
    if (tree / "package.xml").is_file():
        return tree
    tree.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{commit[:12]}.", dir=tree.parent))
    try:
        archive = staging / "tree.tar"
        subprocess.run(["git", "-C", str(REPO), "archive", "--format=tar", "-o", str(archive), commit], check=True)
        with tarfile.open(archive) as handle:
            handle.extractall(staging / "tree")  # our own repository's files
        archive.unlink()
        try:
            (staging / "tree").rename(tree)
        except OSError:  # another bench got there first
            if not (tree / "package.xml").is_file():
                raise
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return tree


def reference_environment(tree: Path, base: Optional[Dict[str, str]] = None) -> Dict[str, str]:
    """The environment that makes a Python child import ``fr5_rl`` from ``tree`` (and find its
    config there) instead of this checkout.

    :param base: the environment to start from (default: this process's).
    """
    env = dict(os.environ if base is None else base)
    ours = str(REPO / "src")
    others = [entry for entry in env.get("PYTHONPATH", "").split(os.pathsep) if entry and entry != ours]
    env["PYTHONPATH"] = os.pathsep.join([str(tree / "src"), *others])
    env["FR5_RL_ROOT"] = str(tree)
    return env


def alternating(index: int) -> Tuple[str, str]:
    """The order of run ``index``'s pair: ``("new", "old")``, then ``("old", "new")``, and so on.
    Alternating which code goes first, as well as alternating the codes, lets a machine that
    speeds up or slows down mid-run touch both alike."""
    return ("new", "old") if index % 2 == 0 else ("old", "new")
