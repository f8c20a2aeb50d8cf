"""What a model directory is: its files, its ``meta.json``, how it is written and checked.

A model directory holds:

==================== ======================================================== ===========
file                 what                                                     loads code?
==================== ======================================================== ===========
``meta.json``        task, algorithm, observation/action sizes, the env and   no (JSON)
                     robot configuration it was trained with, provenance
``model.onnx``       actor with normalisation folded in: raw obs -> action    no (protobuf)
``model.zip``        Stable-Baselines3 model                                  **yes** (pickled objects)
``vecnormalize.pkl`` observation normalisation statistics                     **yes** (pickle)
``eval.json``        (after evaluation) success rate and how it was measured  no (JSON)
==================== ======================================================== ===========

Pickles run code when they are loaded. The ``onnx`` backend reads only ``meta.json`` and
``model.onnx``; take ``model.zip`` and ``vecnormalize.pkl`` only from someone you trust.

Training and deployment both import this module; it imports neither. Every problem with a
model directory is a :class:`ModelFilesError` whose message names the file, says what is wrong
and what to do: callers print it as one line.
"""
from __future__ import annotations

import json
import os
import platform
import shutil
import signal
import tempfile
import threading
import zipfile
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Dict, Iterator, Mapping, Optional, Tuple, Type

from ..config import DEFAULT_ROBOT, check_robot_name, package_root, robot_config
from ..env_config import EnvConfig

MODEL_FILE = "model.zip"
STATS_FILE = "vecnormalize.pkl"
META_FILE = "meta.json"
ONNX_FILE = "model.onnx"
EVAL_FILE = "eval.json"

ALGORITHMS = ("ppo", "sac", "td3", "tqc")
BACKENDS = ("torch", "onnx")
# meta.json fields every loader relies on, with their JSON types.
REQUIRED_META = {"task": str, "algo": str, "robot": str, "observation_size": int, "action_size": int}
# Entries Stable-Baselines3 writes into every model.zip.
_SB3_ZIP_ENTRIES = ("data", "policy.pth")


class ModelFilesError(RuntimeError):
    """A model directory is incomplete, damaged or does not match this code; the message says
    which file, what is wrong and what to do."""


def algorithm_class(name: str) -> Type:
    """Stable-Baselines3 (or sb3-contrib) class for ``ppo``, ``sac``, ``td3`` or ``tqc``.

    :param name: algorithm name, case-insensitive.
    :raises ValueError: for an unknown name.
    """
    name = name.lower()
    if name in ("ppo", "sac", "td3"):
        import stable_baselines3

        return getattr(stable_baselines3, name.upper())
    if name == "tqc":
        from sb3_contrib import TQC

        return TQC
    raise ValueError(f"unknown algorithm '{name}'; choose one of {', '.join(ALGORITHMS)}")


def machine_description() -> Dict[str, Any]:
    """The machine figures are measured on: cpu model, core count, Python, platform."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", "r", encoding="utf-8") as stream:
            for line in stream:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(),
            "platform": platform.platform()}


def build_meta(task: str, algo: str, env_overrides: Mapping[str, Any], env_config: EnvConfig,
               observation_size: int, action_size: int, control_dt: float,
               seed: int, **extra: Any) -> Dict[str, Any]:
    """The ``meta.json`` of a model: written here only, whoever trained it.

    :param env_overrides: the overrides the model was trained with (merged over env.yaml); they
        name the arm (``robot``), so that a loader builds the same configuration.
    :param env_config: the resulting environment configuration, checked again at load time. Its
        arm's description (``config/robots/<robot>.yaml`` with the gripper) is saved as
        ``robot_config`` and its name as ``robot``.
    :param control_dt: control period (s) the model was trained at.
    :param extra: further provenance (e.g. ``n_envs``, ``trained_by``, ``num_timesteps``).
    """
    meta = {"task": task, "algo": algo, "robot": env_config.robot,
            "env_overrides": {**dict(env_overrides), "robot": env_config.robot}, "env_config": env_config.to_dict(),
            "robot_config": robot_config(env_config.robot), "observation_size": int(observation_size),
            "action_size": int(action_size), "control_dt": float(control_dt), "seed": int(seed)}
    meta.update(extra)
    return meta


def write_json_atomic(path: Path, data: Mapping[str, Any]) -> None:
    """Write JSON through a temp file + rename, so a crash never leaves half a file."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    with os.fdopen(fd, "w", encoding="utf-8") as stream:
        json.dump(data, stream, indent=2, sort_keys=True)
        stream.write("\n")
    os.chmod(tmp, 0o644)  # mkstemp makes it private; these are ordinary results
    os.replace(tmp, path)


@contextmanager
def interrupts_deferred() -> Iterator[None]:
    """Hold Ctrl-C (SIGINT) back while the block runs, then act on it as it would have.

    A Ctrl-C half-way through ``model.save`` leaves torch's zip writer in an error of its own,
    raised in place of the KeyboardInterrupt: the trainer then crashed instead of saving its
    checkpoint and exiting 130. Only the main thread receives signals; elsewhere this does nothing.
    """
    if threading.current_thread() is not threading.main_thread() or signal.getsignal(signal.SIGINT) is None:
        yield  # no signals here, or a handler Python did not install and could not put back
        return
    received = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: received.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if received:
        if callable(previous):
            previous(signal.SIGINT, None)  # Python's handler raises KeyboardInterrupt
        elif previous != signal.SIG_IGN:
            os.kill(os.getpid(), signal.SIGINT)  # the default action, now that it is back


def save_model_dir(directory: Path, model, vec_normalize, meta: Mapping[str, Any],
                   write_extra: Optional[Callable[[Path], None]] = None) -> Path:
    """Save model + statistics + meta (+ whatever ``write_extra(staging_dir)`` writes) together.

    Everything is written into a staging directory beside the target, which then replaces the
    target by renames; the previous version stays as ``.<name>.old`` until the new one is in
    place, and :func:`recover_model_dir` brings it back after a crash in between. A Ctrl-C
    meanwhile takes effect once the save is done (:func:`interrupts_deferred`).
    """
    with interrupts_deferred():
        return _save_model_dir(Path(directory), model, vec_normalize, meta, write_extra)


def _save_model_dir(directory: Path, model, vec_normalize, meta: Mapping[str, Any],
                    write_extra: Optional[Callable[[Path], None]]) -> Path:
    directory.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(dir=directory.parent, prefix=f".{directory.name}."))
    umask = os.umask(0)
    os.umask(umask)
    staging.chmod(0o777 & ~umask)  # mkdtemp makes it private; a model directory is an ordinary one
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


def required_files(backend: str) -> tuple:
    """Files a backend reads: ``onnx`` needs no pickle, ``torch`` needs the SB3 files."""
    if backend == "onnx":
        return (META_FILE, ONNX_FILE)
    if backend == "torch":
        return (META_FILE, MODEL_FILE, STATS_FILE)
    raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, got '{backend}'")


def check_files_present(directory: Path, backend: str) -> None:
    """Refuse a directory that lacks a file ``backend`` reads, saying how to get it."""
    directory = Path(directory)
    if not directory.is_dir():
        raise ModelFilesError(f"{directory}: no such model directory; pass the directory that holds {META_FILE}")
    check_not_a_run(directory)
    for name in required_files(backend):
        if name == META_FILE or (directory / name).is_file():
            continue  # meta.json: read_meta says what is wrong with it
        remedy = {
            ONNX_FILE: f"run `rosrun fr5_rl export_onnx.py {directory}`, or use --backend torch",
            MODEL_FILE: "copy the complete model directory, or use --backend onnx if it has model.onnx",
            STATS_FILE: "the normalisation statistics must be saved with the model (train.py does this); "
                        "without them the policy would see un-normalised observations and act wrongly",
        }[name]
        raise ModelFilesError(f"{directory / name} is missing: {remedy}")


def check_not_a_run(directory: Path) -> None:
    """Refuse a training run's directory (``train.py``'s or ``imitate.py``'s) given as a model,
    naming the model inside it."""
    if not (directory / META_FILE).is_file() and (directory / "final" / META_FILE).is_file():
        raise ModelFilesError(f"{directory} is a training run, not a model: its model is {directory / 'final'} "
                              f"(the best evaluated one: {directory / 'best'})")


def resolve_model_dir(path: str | Path, caller_dir: Optional[str | Path] = None) -> Path:
    """Where a model directory given by a user is: an absolute path as it is; a relative one in the
    caller's directory, else in the package (``models/reach`` from anywhere), as ``rosrun``,
    ``roslaunch`` and the Python API all take it.

    :param caller_dir: the directory the user typed the path in (a node started by roslaunch runs
        elsewhere: the launch passes it); None: the current directory.
    :raises ModelFilesError: neither place holds the directory; the message names both.
    """
    path = Path(path)
    if path.is_absolute():
        candidates = [path]
    else:
        candidates = [Path(caller_dir or Path.cwd()) / path, package_root() / path]
    for candidate in candidates:
        if candidate.is_dir():
            return candidate
    raise ModelFilesError(f"no such model directory: {path} (looked in {' and '.join(str(c) for c in candidates)})")


# The settings of a model's training (meta.json env_overrides) that stay wherever it runs: its
# observation and action, and the objects it was trained to handle (object.variety).
DEPLOYMENT_SETTINGS = (("robot",), ("simulation", "control_dt"), ("action",), ("observation",), ("object", "variety"))


def deployment_overrides(meta: Mapping[str, Any]) -> Dict[str, Any]:
    """The part of a model's training overrides (``meta.json`` ``env_overrides``) that its
    observation, action and objects depend on (:data:`DEPLOYMENT_SETTINGS`), without its
    randomisation or reward: what an evaluation or a simulator of the registered task keeps."""
    overrides = meta.get("env_overrides") or {}
    kept: Dict[str, Any] = {}
    for path in DEPLOYMENT_SETTINGS:
        value: Any = overrides
        for key in path:
            value = value.get(key) if isinstance(value, dict) else None
        if value is not None:
            node = kept
            for key in path[:-1]:
                node = node.setdefault(key, {})
            node[path[-1]] = value
    return kept


def task_and_arm(model_dir: Optional[str | Path], task: Optional[str] = None,
                 robot: Optional[str] = None, caller_dir: Optional[str | Path] = None) -> Tuple[str, str]:
    """The task and the arm a launch or a tool runs: the model's (its ``meta.json``), which
    ``task`` and ``robot`` must not contradict; without a model, those given or the defaults
    (``reach``, ``fr5``).

    :raises ModelFilesError: the model is missing or damaged, or was trained on another task or
        for another arm; the message says what to pass instead.
    :raises ConfigError: an unknown arm.
    """
    if model_dir is None:
        return task or "reach", check_robot_name(robot or DEFAULT_ROBOT)
    meta = read_meta(resolve_model_dir(model_dir, caller_dir))
    if task is not None and task != meta["task"]:
        raise ModelFilesError(f"{model_dir} was trained on '{meta['task']}', not '{task}': pass a {task} model, or "
                              "leave the task out to use the model's")
    if robot is not None and robot != meta["robot"]:
        raise ModelFilesError(f"{model_dir} was trained for the {meta['robot']}, not the {robot}: pass a model "
                              f"trained for the {robot}, or leave robot out to use the model's")
    return meta["task"], check_robot_name(meta["robot"])


def arm_of(model_dir: Optional[str | Path], robot: Optional[str]) -> str:
    """The arm a launch or a tool runs (:func:`task_and_arm`'s)."""
    return task_and_arm(model_dir, None, robot)[1]


def read_meta(directory: Path) -> Dict[str, Any]:
    """Read and check ``meta.json``: valid JSON, an object, with the fields loaders rely on."""
    path = Path(directory) / META_FILE
    if not path.is_file():
        check_not_a_run(Path(directory))
        raise ModelFilesError(f"{path} is missing: copy the complete model directory, or re-run the training "
                              "that made it")
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError:
        raise ModelFilesError(f"{path} is not text: the file is damaged; copy it again from the original") from None
    except json.JSONDecodeError as error:
        raise ModelFilesError(f"{path} is not valid JSON ({error.msg} at line {error.lineno}, column "
                              f"{error.colno}): the file is damaged; copy it again from the original") from None
    if not isinstance(meta, dict):
        raise ModelFilesError(f"{path} must hold a JSON object, not {type(meta).__name__}: copy it again "
                              "from the original")
    for key, kind in REQUIRED_META.items():
        if key not in meta:
            raise ModelFilesError(f"{path} lacks '{key}': it was not written by this version of fr5_rl; "
                                  "re-run the training that made it")
        value = meta[key]
        if not isinstance(value, kind) or isinstance(value, bool):
            raise ModelFilesError(f"{path}: '{key}' must be a {kind.__name__}, got {value!r}: copy it again "
                                  "from the original")
    if meta["algo"] not in ALGORITHMS:
        raise ModelFilesError(f"{path}: unknown algorithm '{meta['algo']}' (known: {', '.join(ALGORITHMS)})")
    return meta


def check_sb3_zip(path: Path) -> None:
    """Refuse a ``model.zip`` that is not a complete Stable-Baselines3 archive, before SB3 reads it."""
    problem = None
    if not zipfile.is_zipfile(path):
        problem = "is not a zip archive (truncated or overwritten)"
    else:
        try:
            with zipfile.ZipFile(path) as archive:
                names = set(archive.namelist())
                missing = [name for name in _SB3_ZIP_ENTRIES if name not in names]
                if missing:
                    problem = f"is a zip archive but not a Stable-Baselines3 model (no {', '.join(missing)})"
                elif archive.testzip() is not None:
                    problem = f"is damaged (entry {archive.testzip()} fails its checksum)"
        except (zipfile.BadZipFile, OSError, EOFError) as error:
            problem = f"cannot be read as a zip archive ({error})"
    if problem:
        raise ModelFilesError(f"{path} {problem}: copy model.zip again from the original, or re-run training")


def damaged(path: Path, error: BaseException, what: str) -> ModelFilesError:
    """The error for a file that exists but could not be loaded."""
    detail = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
    return ModelFilesError(f"{path} could not be loaded as {what} ({type(error).__name__}: {detail[:160]}): "
                           f"the file is damaged or from an incompatible version; copy it again from the original "
                           "or re-run training")
