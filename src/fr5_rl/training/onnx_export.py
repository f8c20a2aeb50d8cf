"""Exporting a model directory's actor to ONNX: what ``rosrun fr5_rl export_onnx.py`` runs.

The graph takes the *raw* observation (batch, obs_size) and returns the deterministic action
(batch, 7) in [-1, 1]: the VecNormalize statistics are folded in, so onnxruntime needs nothing
else. ``--check N`` compares it with SB3 ``predict`` on N observations from real rollouts.
"""
from __future__ import annotations

import warnings
from pathlib import Path
from typing import List

import numpy as np

from ..deploy.bundle import ONNX_FILE, check_files_present, read_meta


def build_actor_module(model, normalizer):
    """torch.nn.Module: raw observation -> normalised -> deterministic action in [-1, 1]."""
    import torch

    mean = torch.as_tensor(normalizer.obs_rms.mean, dtype=torch.float32)
    std = torch.sqrt(torch.as_tensor(normalizer.obs_rms.var, dtype=torch.float32) + float(normalizer.epsilon))
    clip = float(normalizer.clip_obs)
    policy = model.policy
    kind = type(model).__name__

    class Actor(torch.nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.policy = policy
            self.register_buffer("mean", mean)
            self.register_buffer("std", std)

        def forward(self, observation):
            normalised = torch.clamp((observation - self.mean) / self.std, -clip, clip)
            if kind == "PPO":
                features = self.policy.extract_features(normalised, self.policy.pi_features_extractor)
                latent = self.policy.mlp_extractor.forward_actor(features)
                action = self.policy.action_net(latent)
            elif kind == "TD3":
                action = self.policy.actor(normalised)
            else:  # SAC, TQC: tanh-squashed Gaussian mean
                action = self.policy.actor(normalised, deterministic=True)
            return torch.clamp(action, -1.0, 1.0)

    return Actor().eval()


def export(model_dir: Path) -> Path:
    """Export MODEL_DIR's actor to MODEL_DIR/model.onnx; returns the path."""
    import torch

    from ..deploy.policy import TorchPolicy, check_meta_matches_code

    check_files_present(model_dir, "torch")
    meta = read_meta(model_dir)
    check_meta_matches_code(model_dir, meta)
    torch_policy = TorchPolicy(model_dir, meta)
    module = build_actor_module(torch_policy.model, torch_policy.normalizer)
    example = torch.zeros(1, int(meta["observation_size"]), dtype=torch.float32)
    path = Path(model_dir) / ONNX_FILE
    tmp = path.with_suffix(".onnx.tmp")
    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")  # the TorchScript exporter's deprecation notice
        torch.onnx.export(module, (example,), str(tmp), dynamo=False, input_names=["observation"],
                          output_names=["action"], dynamic_axes={"observation": {0: "batch"}, "action": {0: "batch"}},
                          opset_version=17)
    tmp.replace(path)
    return path


def rollout_observations(task: str, env_overrides, policy, count: int, seed: int = 123) -> np.ndarray:
    """``count`` raw observations visited by ``policy`` in the real environment."""
    from ..envs import FR5Env

    env = FR5Env(task=task, config=env_overrides)
    observations: List[np.ndarray] = []
    obs, _ = env.reset(seed=seed)
    episode = 0
    while len(observations) < count:
        observations.append(obs.copy())
        obs, _, terminated, truncated, _ = env.step(policy.act(obs))
        if terminated or truncated:
            episode += 1
            obs, _ = env.reset(seed=seed + episode)
    env.close()
    return np.stack(observations)


PARITY_TOLERANCE = 1e-5  # max |delta action| between the ONNX graph and the SB3 model


def parity(model_dir: Path, count: int = 1000) -> float:
    """max |action_onnx - action_sb3| over ``count`` rollout observations."""
    from ..deploy.policy import load_policy

    torch_policy = load_policy(model_dir, "torch")
    onnx_policy = load_policy(model_dir, "onnx")
    observations = rollout_observations(torch_policy.task, torch_policy.meta.get("env_overrides", {}),
                                        torch_policy, count)
    return float(max(np.max(np.abs(torch_policy.act(o) - onnx_policy.act(o))) for o in observations))
