"""One typed loader per kind of configuration file: unknown keys, missing keys and wrong types
are refused with the key's path; defaults live in the YAML files only."""
from pathlib import Path

import pytest
import yaml

from fr5_rl.config import ConfigError, load_typed, load_yaml, typed
from fr5_rl.deploy.policy_node_params import PolicyNodeParams
from fr5_rl.sim.node_params import SimNodeParams
from fr5_rl.training.algorithms import check_hyperparameters, load_hyperparameters
from fr5_rl.training.hyperparameters import DaggerConfig, Hyperparameters
from fr5_rl.transforms import StaticTransforms, load_static_transforms

ROOT = Path(__file__).resolve().parent.parent
KINDS = [(PolicyNodeParams, "policy_node"), (SimNodeParams, "sim_node"), (StaticTransforms, "static_transforms"),
         (Hyperparameters, "ppo_reach"), (Hyperparameters, "tqc_grasp"), (DaggerConfig, "dagger_grasp")]


@pytest.mark.parametrize("cls, name", KINDS, ids=[k[1] for k in KINDS])
def test_shipped_files_load(cls, name):
    assert isinstance(load_typed(cls, name), cls)


# Every YAML file load_yaml reads in this package: configs, and the published driver profiles
# and calibrations (read back by fit_driver.py and the benches).
SHIPPED_YAML = sorted([*ROOT.glob("config/**/*.yaml"), *ROOT.glob("docs/bench/**/*.yaml")])


def typed_tree(value):
    """``value`` with every leaf as (type name, value): 1 and 1.0 compare unequal."""
    if isinstance(value, dict):
        return {key: typed_tree(item) for key, item in value.items()}
    if isinstance(value, list):
        return [typed_tree(item) for item in value]
    return (type(value).__name__, value)


@pytest.mark.parametrize("path", SHIPPED_YAML, ids=[str(p.relative_to(ROOT)) for p in SHIPPED_YAML])
def test_shipped_yaml_reads_the_same_through_libyaml_and_pure_python(path):
    """load_yaml parses with libyaml where PyYAML has it (ten times faster); both parsers must
    give every shipped file the same values, types included."""
    text = path.read_text(encoding="utf-8")
    python = typed_tree(yaml.load(text, Loader=yaml.SafeLoader) or {})
    assert typed_tree(load_yaml(path)) == python
    if hasattr(yaml, "CSafeLoader"):  # PyYAML without libyaml: load_yaml is the pure-Python parser
        assert typed_tree(yaml.load(text, Loader=yaml.CSafeLoader) or {}) == python


def test_malformed_yaml_is_an_error_that_names_the_line(tmp_path):
    path = tmp_path / "broken.yaml"
    path.write_text("a: 1\nb: [2, 3\nc: 4\n")
    with pytest.raises(yaml.YAMLError, match="line"):
        load_yaml(path)


def write(tmp_path: Path, data) -> Path:
    path = tmp_path / "file.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def mutated(name: str, change):
    data = load_yaml(name)
    change(data)
    return data


@pytest.mark.parametrize("cls, name, change, words", [
    (PolicyNodeParams, "policy_node", lambda d: d.update(modle_dir="x"), "unknown key 'modle_dir'"),
    (PolicyNodeParams, "policy_node", lambda d: d.update(rate="fast"), "'rate' must be a number"),
    (PolicyNodeParams, "policy_node", lambda d: d.update(command_gripper="yes"), "'command_gripper' must be true or false"),
    (PolicyNodeParams, "policy_node", lambda d: d.update(backend="tensorrt"), "'backend' must be torch or onnx"),
    (PolicyNodeParams, "policy_node", lambda d: d.pop("target_timeout"), "missing key 'target_timeout'"),
    (SimNodeParams, "sim_node", lambda d: d.update(seed=1.5), "'seed' must be an integer"),
    (SimNodeParams, "sim_node", lambda d: d.update(task="stack"), "'task' must be one of reach, grasp, place or"),
    (StaticTransforms, "static_transforms", lambda d: d["transforms"][0].update(xyz=[0, 0]), "transforms[0]"),
    (StaticTransforms, "static_transforms", lambda d: d["transforms"][1].update(parnet="x"), "unknown key 'transforms[1].parnet'"),
    (StaticTransforms, "static_transforms", lambda d: d["transforms"][0].update(rpy=[0, "a", 0]), "'transforms[0].rpy[1]' must be a number"),
    (Hyperparameters, "ppo_reach", lambda d: d["normalize"].update(norm_obs="on"), "'normalize.norm_obs' must be true or false"),
    (Hyperparameters, "ppo_reach", lambda d: d.update(n_timestep=5), "unknown key 'n_timestep'"),
    (Hyperparameters, "ppo_reach", lambda d: d["env"].update(randomization={}), "'env'"),
    (Hyperparameters, "ppo_reach", lambda d: d.pop("n_envs"), "missing key 'n_envs'"),
    (DaggerConfig, "dagger_grasp", lambda d: d["dagger"].pop("rounds"), "missing key 'dagger.rounds'"),
    (DaggerConfig, "dagger_grasp", lambda d: d["dagger"].update(rounds="many"), "'dagger.rounds' must be an integer"),
    (DaggerConfig, "dagger_grasp", lambda d: d["dagger"].update(expert_share_decay=2.0), "expert_share_decay"),
    (DaggerConfig, "dagger_grasp", lambda d: d["dagger"].update(learning_rate_schedule="step"), "use one of constant, cosine"),
    (DaggerConfig, "dagger_grasp", lambda d: d["dagger"].update(gripper_loss_weight=0.0), "'gripper_loss_weight' must be positive"),
], ids=lambda v: v if isinstance(v, str) and " " in v else "")
def test_bad_files_are_refused_with_the_key_path(tmp_path, cls, name, change, words):
    path = write(tmp_path, mutated(name, change))
    with pytest.raises(ConfigError) as caught:
        load_typed(cls, path)
    assert words in str(caught.value) and str(path) in str(caught.value), str(caught.value)


def test_algo_kwargs_names_are_checked_against_the_algorithm(tmp_path):
    hyper = load_hyperparameters("ppo", "reach", write(tmp_path, mutated("ppo_reach", lambda d: d["algo_kwargs"].update(n_step=512))))
    with pytest.raises(ConfigError, match="unknown key 'algo_kwargs.n_step' for PPO"):
        check_hyperparameters("ppo", hyper, hyper.n_envs)
    hyper = load_hyperparameters("ppo", "reach", write(tmp_path, mutated("ppo_reach", lambda d: d["algo_kwargs"].update(seed=3))))
    with pytest.raises(ConfigError, match="set by train.py"):
        check_hyperparameters("ppo", hyper, hyper.n_envs)


def test_hyperparameters_round_trip_through_a_run_config():
    hyper = load_hyperparameters("ppo", "reach")
    assert typed(Hyperparameters, hyper.to_dict(), "config.json") == hyper


def test_static_transforms_loader_gives_matrices():
    entries = load_static_transforms()
    camera = next(e for e in entries if e["child"] == "camera_link")
    assert camera["matrix"].shape == (4, 4) and camera["matrix"][2, 3] == pytest.approx(camera["xyz"][2])


@pytest.mark.parametrize("key, value", [("command_delay_s", [0.01, 0.005]), ("observation_age_s", [-0.01, 0.0]),
                                        ("command_delay_s", [0.0, 0.05])])
def test_period_timing_ranges_are_checked(key, value):
    """A command delay or observation age is a time inside one 20 ms period, low <= high."""
    from fr5_rl.env_config import load_env_config

    with pytest.raises(ConfigError, match=key):
        load_env_config({"randomisation": {key: value}})


@pytest.mark.parametrize("value", [-1, 5, 1.5, True, "2"])
def test_previous_actions_must_be_a_small_whole_number(value):
    from fr5_rl.env_config import load_env_config

    with pytest.raises(ConfigError, match="previous_actions"):
        load_env_config({"observation": {"previous_actions": value}})
    assert load_env_config({"observation": {"previous_actions": 3}}).observation.previous_actions == 3


def test_whole_multiple():
    from fr5_rl.config import whole_multiple

    assert whole_multiple(0.02, 0.004) == 5 and whole_multiple(0.008, 0.004) == 2
    assert whole_multiple(0.02, 0.003) is None and whole_multiple(0.002, 0.004) is None
    assert whole_multiple(0.02, 0.0) is None


def test_the_environment_models_the_deployed_chains_own_settings_and_records_them(tmp_path):
    """EnvConfig.deployed is read from the nodes' files (one source), lands in meta.json, and is
    what the environment's chain runs; an override reaches the chain."""
    from fr5_rl.deploy.bundle import build_meta
    from fr5_rl.env_config import load_env_config
    from fr5_rl.envs import FR5Env
    from fr5_rl.gripper import load_bridge_timing
    from fr5_rl.motion_guard import load_guard_settings

    cfg = load_env_config()
    assert cfg.deployed.guard == load_guard_settings() and cfg.deployed.bridge == load_bridge_timing()
    meta = build_meta("reach", "ppo", {}, cfg, 1, 7, 0.02, 0)
    assert meta["env_config"]["deployed"]["guard"]["ramp_time"] == load_guard_settings().ramp_time
    assert meta["env_config"]["deployed"]["bridge"]["call_period"] == load_bridge_timing().call_period
    env = FR5Env("reach", config={"randomisation": {"enabled": True, "guard_share": 1.0},
                                  "deployed": {"guard": {"ramp_time": 1.25}}})
    try:
        assert env.episode.chain.guard.settings.ramp_time == 1.25
    finally:
        env.close()
