"""Loading a trained policy for inference: what the ROS policy node and evaluation use.

``load_policy(model_dir, backend)`` returns a :class:`Policy` whose ``act`` takes the *raw*
observation (as built by :mod:`fr5_rl.observation`) and returns the deterministic action.

Backends:

- ``onnx``: ``model.onnx`` on onnxruntime, normalisation folded into the graph. Reads only
  ``meta.json`` and ``model.onnx``, so it loads no pickle and imports neither torch nor SB3.
- ``torch``: the SB3 ``model.zip`` with its ``vecnormalize.pkl`` statistics (both pickles:
  take them only from someone you trust).

Every problem with the files is a :class:`~fr5_rl.deploy.bundle.ModelFilesError` that names
the file and says what to do.
"""
from __future__ import annotations

import pickle
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional

import numpy as np

from ..config import robot_config, robot_names
from ..env_config import TASK_NAMES, EnvConfig, load_env_config
from ..control import ACTION_SIZE
from ..observation import observation_size
from .bundle import (DEPLOYMENT_SETTINGS, META_FILE, MODEL_FILE, ONNX_FILE, STATS_FILE, ModelFilesError,
                     algorithm_class, deployment_overrides, check_files_present, check_sb3_zip, damaged, read_meta, resolve_model_dir)

TASKS = TASK_NAMES  # a model of any task loads (the policy node then says what it can run)


class Policy:
    """Deterministic policy: raw observation (shape (obs_size,)) -> action (7,) in [-1, 1]."""

    backend = "none"

    def __init__(self, meta: Mapping[str, Any]) -> None:
        self.meta = dict(meta)
        self.observation_size = int(meta["observation_size"])
        self.action_size = int(meta["action_size"])
        self.task = str(meta["task"])

    def deployment_overrides(self) -> Dict[str, Any]:
        """:func:`~fr5_rl.deploy.bundle.deployment_overrides` of this model: what an evaluation of
        the registered task keeps, so that the environment builds what the policy takes."""
        return deployment_overrides(self.meta)

    def act(self, observation: np.ndarray) -> np.ndarray:
        """The deterministic action for one raw observation.

        :raises ValueError: wrong length, NaN or inf.
        """
        observation = np.asarray(observation, dtype=np.float32).reshape(-1)
        if observation.shape != (self.observation_size,):
            raise ValueError(f"policy expects {self.observation_size} observation values, got {observation.shape[0]}")
        if not np.all(np.isfinite(observation)):
            raise ValueError("observation contains NaN or inf")
        action = self._act(observation)
        return np.clip(action, -1.0, 1.0)

    def _act(self, observation: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError


def load_normalizer(model_dir: Path):
    """The pickled VecNormalize of a model directory, usable without its environment.

    :raises ModelFilesError: the file is not a readable VecNormalize pickle.
    """
    path = Path(model_dir) / STATS_FILE
    try:
        with open(path, "rb") as stream:
            normalizer = pickle.load(stream)
    except Exception as error:  # a damaged pickle can raise nearly anything
        raise damaged(path, error, "VecNormalize statistics") from None
    rms = getattr(normalizer, "obs_rms", None)
    if rms is None or not hasattr(rms, "mean") or not hasattr(normalizer, "normalize_obs"):
        raise ModelFilesError(f"{path} holds a {type(normalizer).__name__}, not VecNormalize statistics: "
                              "copy vecnormalize.pkl again from the model's original directory")
    normalizer.training = False
    return normalizer


class TorchPolicy(Policy):
    """SB3 model on the CPU with its observation normalisation."""

    backend = "torch"

    def __init__(self, model_dir: Path, meta: Mapping[str, Any]) -> None:
        super().__init__(meta)
        import torch

        torch.set_num_threads(1)
        self.normalizer = load_normalizer(model_dir)
        if np.shape(self.normalizer.obs_rms.mean) != (self.observation_size,):
            raise ModelFilesError(
                f"{Path(model_dir) / STATS_FILE} holds statistics of {np.size(self.normalizer.obs_rms.mean)} "
                f"observation values, {META_FILE} says {self.observation_size}: the files come from different "
                "models; copy the complete directory again")
        path = Path(model_dir) / MODEL_FILE
        check_sb3_zip(path)
        try:
            self.model = algorithm_class(meta["algo"]).load(path, device="cpu")
        except Exception as error:
            raise damaged(path, error, f"a Stable-Baselines3 {str(meta['algo']).upper()} model") from None
        if self.model.observation_space.shape != (self.observation_size,):
            raise ModelFilesError(f"{path} expects observations of shape {self.model.observation_space.shape}, "
                                  f"{META_FILE} says {self.observation_size}: the files come from different models")
        if self.model.action_space.shape != (self.action_size,):
            raise ModelFilesError(f"{path} produces actions of shape {self.model.action_space.shape}, "
                                  f"{META_FILE} says {self.action_size}: the files come from different models")

    def normalize(self, observation: np.ndarray) -> np.ndarray:
        return self.normalizer.normalize_obs(observation).astype(np.float32)

    def _act(self, observation: np.ndarray) -> np.ndarray:
        action, _ = self.model.predict(self.normalize(observation), deterministic=True)
        return np.asarray(action, dtype=np.float64)


class OnnxPolicy(Policy):
    """``model.onnx`` (raw observation in, action out) on onnxruntime, one CPU thread."""

    backend = "onnx"

    def __init__(self, model_dir: Path, meta: Mapping[str, Any]) -> None:
        super().__init__(meta)
        import onnxruntime as ort

        path = Path(model_dir) / ONNX_FILE
        options = ort.SessionOptions()
        options.intra_op_num_threads = 1
        options.inter_op_num_threads = 1
        options.log_severity_level = 4  # errors come back as exceptions; no C++ log lines
        try:
            self.session = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
        except Exception as error:
            raise damaged(path, error, "an ONNX model") from None
        inputs, outputs = self.session.get_inputs(), self.session.get_outputs()
        if len(inputs) != 1 or inputs[0].shape[-1] != self.observation_size:
            raise ModelFilesError(f"{path} takes {[i.shape for i in inputs]} as input, {META_FILE} says "
                                  f"{self.observation_size} observation values: re-export it with "
                                  f"`rosrun fr5_rl export_onnx.py {model_dir}`")
        if len(outputs) != 1 or outputs[0].shape[-1] != self.action_size:
            raise ModelFilesError(f"{path} returns {[o.shape for o in outputs]}, {META_FILE} says "
                                  f"{self.action_size} action values: re-export it with "
                                  f"`rosrun fr5_rl export_onnx.py {model_dir}`")
        self._input_name = inputs[0].name

    def _act(self, observation: np.ndarray) -> np.ndarray:
        (action,) = self.session.run(None, {self._input_name: observation.reshape(1, -1)})
        return np.asarray(action[0], dtype=np.float64)


def comparable_action(section: Any) -> Any:
    """An ``action`` section as it bears on a model: a model saved before ``action.space`` and
    ``action.gripper`` existed was trained in joint space with the opening width, and the tcp
    steps' scale means nothing in joint space."""
    if not isinstance(section, dict):
        return section
    section = {"space": "joint", "gripper": "width", **section}
    if section["space"] == "joint":
        section = {key: value for key, value in section.items() if not key.startswith("max_tcp_")}
    return section


def config_mismatches(meta: Mapping[str, Any], current_env: Optional[EnvConfig] = None) -> List[str]:
    """Differences between the configuration a model was trained with and the current one.

    :param current_env: env.yaml merged with the model's overrides, if already loaded.
    """
    differences = []
    saved_env = meta.get("env_config")
    if saved_env is not None:
        if current_env is None:
            current_env = load_env_config(meta.get("env_overrides", {}))
        current_dict = current_env.to_dict()
        for path in DEPLOYMENT_SETTINGS:
            saved, current = saved_env, current_dict
            for key in path:
                saved = saved.get(key) if isinstance(saved, dict) else None
                current = current.get(key) if isinstance(current, dict) else None
            if path == ("action",):
                saved, current = comparable_action(saved), comparable_action(current)
            if saved != current:
                differences.append(f"env {'.'.join(path)}: trained with {saved}, now {current}")
    saved_robot = meta.get("robot_config")
    if saved_robot is not None:
        robot = str(meta["robot"])
        current_robot = robot_config(robot)
        # The cell is env_config's (compared above); the title is words.
        for key in sorted(set(saved_robot if isinstance(saved_robot, dict) else {}) | set(current_robot)):
            if key in ("cell", "title"):
                continue
            if not isinstance(saved_robot, dict) or saved_robot.get(key) != current_robot.get(key):
                source = "config/gripper.yaml" if key == "gripper" else f"config/robots/{robot}.yaml"
                differences.append(f"{source} '{key}' differs from the one the model was trained with")
    return differences


def check_meta_matches_code(model_dir: Path, meta: Mapping[str, Any], expected_task: Optional[str] = None,
                            expected_robot: Optional[str] = None) -> None:
    """Refuse a model whose task, arm, sizes or deployment settings do not match this code.

    :param expected_task: refuse a model trained on another task (None: any).
    :param expected_robot: refuse a model trained for another arm (None: any).
    """
    path = Path(model_dir) / META_FILE
    task, robot = meta["task"], meta["robot"]
    if task not in TASKS:
        raise ModelFilesError(f"{path}: unknown task '{task}' (this fr5_rl knows {', '.join(TASKS)})")
    if robot not in robot_names():
        raise ModelFilesError(f"{path}: unknown robot '{robot}' (this fr5_rl describes {', '.join(robot_names())})")
    if expected_task is not None and task != expected_task:
        raise ModelFilesError(f"{model_dir} was trained on '{task}', not '{expected_task}': pass a {expected_task} model")
    if expected_robot is not None and robot != expected_robot:
        raise ModelFilesError(f"{model_dir} was trained for the {robot}, not the {expected_robot}: pass a model "
                              f"trained for the {expected_robot}, or leave the robot out to use the model's")
    if meta.get("env_overrides", {}).get("robot") != robot:
        raise ModelFilesError(f"{path}: 'robot' is {robot} but its env_overrides say "
                              f"{meta.get('env_overrides', {}).get('robot')}: the file is damaged; copy it again from the original")
    current_env = load_env_config(meta.get("env_overrides", {}))
    expected_size = observation_size(task, current_env.observation)
    if meta["observation_size"] != expected_size:
        raise ModelFilesError(
            f"{path}: the model takes {meta['observation_size']} observation values but this fr5_rl builds "
            f"{expected_size} for {task} with its settings: it belongs to another version of fr5_rl; retrain it")
    if meta["action_size"] != ACTION_SIZE:
        raise ModelFilesError(
            f"{path}: the model gives {meta['action_size']} action values but this fr5_rl takes {ACTION_SIZE}: "
            "it belongs to another version of fr5_rl; retrain it")
    differences = config_mismatches(meta, current_env)
    if differences:
        raise ModelFilesError(f"{model_dir} does not match the current configuration: " + "; ".join(differences)
                              + ". Restore those settings or retrain the model.")


def load_policy(model_dir: str | Path, backend: str = "torch", expected_task: Optional[str] = None,
                expected_robot: Optional[str] = None) -> Policy:
    """Load a model directory for inference.

    :param model_dir: directory with ``meta.json`` and the backend's files.
    :param backend: ``torch`` or ``onnx``.
    :param expected_task: refuse a model trained on another task.
    :param expected_robot: refuse a model trained for another arm.
    :raises ModelFilesError: a file is missing, damaged, or does not match this code; the
        message names the file and says what to do.
    """
    model_dir = resolve_model_dir(model_dir)
    check_files_present(model_dir, backend)
    meta: Dict[str, Any] = read_meta(model_dir)
    check_meta_matches_code(model_dir, meta, expected_task, expected_robot)
    if backend == "torch":
        return TorchPolicy(model_dir, meta)
    return OnnxPolicy(model_dir, meta)
