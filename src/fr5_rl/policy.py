"""Loading a trained policy for inference: the API the ROS policy node and evaluate.py use.

``load_policy(model_dir, backend)`` returns a :class:`Policy` whose ``act`` takes the *raw*
observation (as built by :mod:`fr5_rl.observation`) and returns the deterministic action.
Backends: ``torch`` (the SB3 model + its VecNormalize statistics) and ``onnx``
(``model.onnx`` run by onnxruntime, normalisation folded into the graph).
"""
from __future__ import annotations

import pickle
from pathlib import Path
from typing import Any, Dict, Optional

import numpy as np

from .training.artifacts import MODEL_FILE, ONNX_FILE, STATS_FILE, ModelFilesError, read_meta


class Policy:
    """Deterministic policy: raw observation (float32, shape (obs_size,)) -> action (7,)."""

    backend = "none"

    def __init__(self, meta: Dict[str, Any]) -> None:
        self.meta = meta
        self.observation_size = int(meta["observation_size"])
        self.action_size = int(meta["action_size"])
        self.task = str(meta["task"])

    def act(self, observation: np.ndarray) -> np.ndarray:
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
    """The pickled VecNormalize of a model directory, usable without its environment."""
    with open(Path(model_dir) / STATS_FILE, "rb") as stream:
        normalizer = pickle.load(stream)
    normalizer.training = False
    return normalizer


class TorchPolicy(Policy):
    """SB3 model on the CPU with its observation normalisation."""

    backend = "torch"

    def __init__(self, model_dir: Path, meta: Dict[str, Any]) -> None:
        super().__init__(meta)
        import torch

        from .training.algorithms import algorithm_class

        torch.set_num_threads(1)
        self.normalizer = load_normalizer(model_dir)
        self.model = algorithm_class(meta["algo"]).load(Path(model_dir) / MODEL_FILE, device="cpu")
        if self.model.observation_space.shape != (self.observation_size,):
            raise ModelFilesError(
                f"{model_dir}: model.zip expects observations of shape {self.model.observation_space.shape}, "
                f"meta.json says {self.observation_size}"
            )

    def normalize(self, observation: np.ndarray) -> np.ndarray:
        return self.normalizer.normalize_obs(observation).astype(np.float32)

    def _act(self, observation: np.ndarray) -> np.ndarray:
        action, _ = self.model.predict(self.normalize(observation), deterministic=True)
        return np.asarray(action, dtype=np.float64)


class OnnxPolicy(Policy):
    """``model.onnx`` (raw observation in, action out) on onnxruntime, one CPU thread."""

    backend = "onnx"

    def __init__(self, model_dir: Path, meta: Dict[str, Any]) -> None:
        super().__init__(meta)
        import onnxruntime as ort

        path = Path(model_dir) / ONNX_FILE
        if not path.is_file():
            raise ModelFilesError(f"{path} is missing: run `rosrun fr5_rl export_onnx.py {model_dir}`")
        options = ort.SessionOptions()
        options.intra_op_num_threads = 1
        options.inter_op_num_threads = 1
        self.session = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
        inputs = self.session.get_inputs()
        if inputs[0].shape[-1] != self.observation_size:
            raise ModelFilesError(f"{path} takes {inputs[0].shape[-1]} observation values, meta.json says {self.observation_size}")
        self._input_name = inputs[0].name

    def _act(self, observation: np.ndarray) -> np.ndarray:
        (action,) = self.session.run(None, {self._input_name: observation.reshape(1, -1)})
        return np.asarray(action[0], dtype=np.float64)


# Settings a trained policy depends on: change one and the observation or the action means
# something else than during training.
DEPLOYMENT_SETTINGS = (("simulation", "control_dt"), ("action",), ("observation",))


def config_mismatches(meta: Dict[str, Any]) -> list:
    """Differences between the configuration a model was trained with and the current one."""
    from .config import load_env_config, load_yaml

    differences = []
    saved_env = meta.get("env_config")
    if saved_env is not None:
        current_env = load_env_config(meta.get("env_overrides", {}))
        for path in DEPLOYMENT_SETTINGS:
            saved, current = saved_env, current_env
            for key in path:
                saved, current = saved.get(key) if saved else None, current.get(key) if current else None
            if saved != current:
                differences.append(f"env {'.'.join(path)}: trained with {saved}, now {current}")
    saved_robot = meta.get("robot_config")
    if saved_robot is not None:
        current_robot = load_yaml("robot")
        for section in ("arm", "gripper", "home_joint_positions"):
            if saved_robot.get(section) != current_robot.get(section):
                differences.append(f"robot.yaml '{section}' differs from the one the model was trained with")
    return differences


def load_policy(model_dir: str | Path, backend: str = "torch", expected_task: Optional[str] = None,
                expected_observation_size: Optional[int] = None) -> Policy:
    """Load a model directory for inference; raises ModelFilesError with a remedy on mismatch."""
    model_dir = Path(model_dir)
    meta = read_meta(model_dir)
    if expected_task is not None and meta["task"] != expected_task:
        raise ModelFilesError(f"{model_dir} was trained on '{meta['task']}', not '{expected_task}'")
    if expected_observation_size is not None and int(meta["observation_size"]) != expected_observation_size:
        raise ModelFilesError(
            f"{model_dir} expects {meta['observation_size']} observation values but this build makes "
            f"{expected_observation_size}: the model belongs to another version of fr5_rl; retrain it"
        )
    differences = config_mismatches(meta)
    if differences:
        raise ModelFilesError(
            f"{model_dir} does not match the current configuration: " + "; ".join(differences)
            + ". Restore those settings or retrain the model."
        )
    if backend == "torch":
        return TorchPolicy(model_dir, meta)
    if backend == "onnx":
        return OnnxPolicy(model_dir, meta)
    raise ValueError(f"backend must be 'torch' or 'onnx', got '{backend}'")
