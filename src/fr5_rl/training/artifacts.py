"""The on-disk model directory: what it holds, how it is written atomically and checked.

A model directory contains:

- ``model.zip``        Stable-Baselines3 model
- ``vecnormalize.pkl`` observation normalisation statistics the model was trained with
- ``meta.json``        task, algorithm, observation/action sizes, env overrides, steps
- ``model.onnx``       (after export) actor with normalisation folded in, raw obs -> action
- ``eval.json``        (after evaluation) success rate and how it was measured
"""
from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any, Callable, Dict, Optional

MODEL_FILE = "model.zip"
STATS_FILE = "vecnormalize.pkl"
META_FILE = "meta.json"
ONNX_FILE = "model.onnx"
EVAL_FILE = "eval.json"


class ModelFilesError(RuntimeError):
    """A model directory is incomplete or does not match what the caller expects."""


def write_json_atomic(path: Path, data: Dict[str, Any]) -> None:
    """Write JSON through a temp file + rename, so a crash never leaves half a file."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    with os.fdopen(fd, "w", encoding="utf-8") as stream:
        json.dump(data, stream, indent=2, sort_keys=True)
        stream.write("\n")
    os.chmod(tmp, 0o644)  # mkstemp makes it private; these are ordinary results
    os.replace(tmp, path)


def save_model_dir(directory: Path, model, vec_normalize, meta: Dict[str, Any],
                   write_extra: Optional[Callable[[Path], None]] = None) -> Path:
    """Save model + statistics + meta (+ whatever ``write_extra(staging_dir)`` writes) together.

    Everything is written into a staging directory beside the target, which then replaces the
    target by renames; the previous version stays as ``.<name>.old`` until the new one is in
    place, and :func:`recover_model_dir` brings it back after a crash in between.
    """
    directory = Path(directory)
    directory.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(dir=directory.parent, prefix=f".{directory.name}."))
    try:
        model.save(staging / MODEL_FILE)
        vec_normalize.save(str(staging / STATS_FILE))
        write_json_atomic(staging / META_FILE, meta)
        if write_extra is not None:
            write_extra(staging)
        if directory.exists():
            old = directory.with_name(f".{directory.name}.old")
            shutil.rmtree(old, ignore_errors=True)
            os.replace(directory, old)
            os.replace(staging, directory)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(staging, directory)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return directory


def recover_model_dir(directory: Path) -> bool:
    """If a crash fell between the two renames of :func:`save_model_dir`, restore the previous
    version. Returns True when ``directory`` holds a model afterwards."""
    directory = Path(directory)
    old = directory.with_name(f".{directory.name}.old")
    if not (directory / MODEL_FILE).is_file() and (old / MODEL_FILE).is_file():
        if directory.exists():
            shutil.rmtree(directory)
        os.replace(old, directory)
    return (directory / MODEL_FILE).is_file()


def read_meta(directory: Path) -> Dict[str, Any]:
    """Read and check ``meta.json`` + the files a loadable model needs; clear errors if not."""
    directory = Path(directory)
    if not directory.is_dir():
        raise ModelFilesError(f"model directory {directory} does not exist")
    missing = [name for name in (MODEL_FILE, STATS_FILE, META_FILE) if not (directory / name).is_file()]
    if missing:
        hint = (
            "the normalisation statistics must be saved with the model (train.py does this); "
            "a model without them would see un-normalised observations and act wrongly"
            if STATS_FILE in missing else "re-run train.py or copy the complete directory"
        )
        raise ModelFilesError(f"{directory} lacks {', '.join(missing)}: {hint}")
    with open(directory / META_FILE, "r", encoding="utf-8") as stream:
        meta = json.load(stream)
    for key in ("task", "algo", "observation_size", "action_size"):
        if key not in meta:
            raise ModelFilesError(f"{directory / META_FILE} lacks '{key}'")
    return meta
