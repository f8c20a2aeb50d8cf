"""One arm's model set from one command (fr5_rl.training.model_set, make_models.py): a tiny
recipe makes, ships, evaluates and describes a model; a second call keeps what was made; a set
killed after training or mid-DAgger continues from there."""
import json

import pytest
import yaml

from fr5_rl.cli import make_models
from fr5_rl.config import ConfigError
from fr5_rl.deploy.policy import load_policy
from fr5_rl.training import imitation
from fr5_rl.training.model_set import ModelSet, load_recipe

pytestmark = pytest.mark.slow  # DAgger runs: `make test`, not `make test-fast`


def _recipe(tmp_path, rounds=1):
    recipe = {
        "seed": 4, "workers": 1,
        "stages": [{"name": "grasp", "task": "grasp", "hyperparams": "dagger_place_tcp", "rounds": rounds,
                    "episodes": 2, "epochs": 1}],
        "evaluation": {"episodes": 2, "seed_start": 1_000_000,
                       "conditions": {"plain": {}, "noisy": {"randomisation": {"enabled": True,
                                                                               "observation_noise_std": 0.005}}},
                       "targets": {"grasp": {"plain": 0.0, "noisy": 0.97}}},
    }
    path = tmp_path / f"recipe_{rounds}.yaml"
    path.write_text(yaml.safe_dump(recipe))
    return path


def _make(tmp_path, recipe, robot="fr3"):
    return make_models.main(["--robot", robot, "--recipe", str(recipe), "--models-dir", str(tmp_path / "models"),
                             "--run-root", str(tmp_path / "runs")])


def test_a_tiny_recipe_makes_a_shipped_evaluated_described_model(tmp_path, capsys):
    recipe = _recipe(tmp_path)
    assert _make(tmp_path, recipe) == 0
    model_dir = tmp_path / "models" / "grasp"
    policy = load_policy(model_dir, "onnx")
    assert policy.meta["robot"] == "fr3" and policy.task == "grasp"
    assert policy.meta["env_overrides"]["action"]["space"] == "tcp"
    plain = json.loads((model_dir / "eval.json").read_text())
    noisy = json.loads((model_dir / "eval_noisy.json").read_text())
    assert plain["episodes"] == noisy["episodes"] == 2 and plain["seeds"] == [1_000_000, 1_000_001]
    assert noisy["condition_overrides"]["randomisation"]["observation_noise_std"] == 0.005
    card = (model_dir / "README.md").read_text()
    assert "# models/fr3/grasp" in card and f"({noisy['successes']}/2;" in card
    assert f"`{recipe}`" in card and policy.meta["recipe"] == str(recipe)  # the recipe it was made by
    assert "≥ 0 %: **met**" in card  # the plain condition's target, met by any model
    assert "`perturbed`:" not in card  # only the conditions it was judged in are described
    assert ("≥ 97 %: **met**" in card) == (noisy["success_rate"] >= 0.97)
    assert ("≥ 97 %: not met" in card) == (noisy["success_rate"] < 0.97)
    summary = json.loads((tmp_path / "models" / "model_set.json").read_text())
    assert summary["robot"] == "fr3" and summary["stages"]["grasp"]["evaluation"]["noisy"]["successes"] == \
        noisy["successes"]
    assert "model set made in" in capsys.readouterr().out


def test_a_second_call_keeps_what_was_made(tmp_path, capsys):
    recipe = _recipe(tmp_path)
    assert _make(tmp_path, recipe) == 0
    model_file = tmp_path / "models" / "grasp" / "model.zip"
    made = model_file.stat().st_mtime_ns
    capsys.readouterr()
    assert _make(tmp_path, recipe) == 0
    assert "made before, kept" in capsys.readouterr().out
    assert model_file.stat().st_mtime_ns == made


def test_a_set_killed_after_training_ships_and_evaluates_without_training_again(tmp_path):
    recipe = _recipe(tmp_path)
    assert _make(tmp_path, recipe) == 0
    progress_path = tmp_path / "runs" / "progress.json"
    progress = json.loads(progress_path.read_text())
    for key in ("evaluation", "card"):
        del progress["stages"]["grasp"][key]
    progress_path.write_text(json.dumps(progress))
    (tmp_path / "models" / "grasp" / "eval.json").unlink()
    summary_path = tmp_path / "runs" / "grasp" / "summary.json"
    trained = summary_path.read_text()
    assert _make(tmp_path, recipe) == 0
    assert summary_path.read_text() == trained
    assert (tmp_path / "models" / "grasp" / "eval.json").is_file()


def test_a_set_killed_mid_dagger_continues_the_stage_from_its_last_round(tmp_path, capsys):
    # The stage's DAgger run got through round 1 of 2 before the kill.
    from fr5_rl.training.run_settings import DaggerRun

    imitation.run_dagger(DaggerRun(task="grasp", hyperparams="dagger_place_tcp", run_dir=tmp_path / "runs" / "grasp",
                                   seed=4, rounds=1, episodes=2, epochs=1, robot="fr3", workers=1))
    capsys.readouterr()
    assert _make(tmp_path, _recipe(tmp_path, rounds=2)) == 0
    assert "resuming" in capsys.readouterr().out
    history = json.loads((tmp_path / "runs" / "grasp" / "summary.json").read_text())["history"]
    assert [h["round"] for h in history] == [0, 1, 2]


def test_misuse_is_refused_with_what_to_do(tmp_path, capsys):
    recipe = _recipe(tmp_path)
    assert make_models.main(["--robot", "fr3", "--recipe", str(recipe), "--stages", "polish"]) == 2
    assert "no stage 'polish' in the recipe; its stages: grasp" in capsys.readouterr().err
    assert _make(tmp_path, recipe, robot="fr3") == 0
    assert _make(tmp_path, recipe, robot="fr10") == 2
    assert "belongs to the fr3's model set" in capsys.readouterr().err
    broken = tmp_path / "broken.yaml"
    broken.write_text(yaml.safe_dump({**yaml.safe_load(recipe.read_text()),
                                      "stages": [{"name": "x", "task": "fly", "hyperparams": "dagger_place_tcp",
                                                  "rounds": 1}]}))
    with pytest.raises(ConfigError, match="task 'fly' is not one of"):
        load_recipe(broken)


def test_the_shipped_recipes_perturbed_world_is_the_fr5_cards():
    """The arms' "perturbed" figures compare with the FR5's "all perturbations" only if they are
    the same world: the recipe's randomisation must be the one models/place was judged in."""
    from fr5_rl.config import package_root

    recipe = load_recipe()
    assert sorted(stage.task for stage in recipe.stages) == ["grasp", "place", "reach"]
    fr5_card = json.loads((package_root() / "docs" / "robustness" / "fr5" / "place_all_together.json").read_text())
    ours = recipe.evaluation.conditions["perturbed"]["randomisation"]
    for key, value in fr5_card["env_overrides"]["randomisation"].items():
        assert ours[key] == value, key
    assert ModelSet("fr10", recipe).models_dir.parts[-2:] == ("models", "fr10")


def test_a_changed_stage_is_refused_until_remade(tmp_path, capsys):
    assert _make(tmp_path, _recipe(tmp_path, rounds=1)) == 0
    summary_path = tmp_path / "runs" / "grasp" / "summary.json"
    first = json.loads(summary_path.read_text())
    # The recipe's stage changed (one more round): the made model no longer answers to it.
    changed = _recipe(tmp_path, rounds=2)
    assert _make(tmp_path, changed) == 2
    assert "--remake grasp" in capsys.readouterr().err
    assert make_models.main(["--robot", "fr3", "--recipe", str(changed), "--models-dir", str(tmp_path / "models"),
                             "--run-root", str(tmp_path / "runs"), "--remake", "grasp"]) == 0
    assert "resuming" not in capsys.readouterr().out  # from nothing, not from the old run
    again = json.loads(summary_path.read_text())
    assert [h["round"] for h in again["history"]] == [0, 1, 2]
    assert [h["round"] for h in first["history"]] == [0, 1]
    # The set's time is the kept stage's own; the first make of it counts only in the machine's.
    made = json.loads((tmp_path / "models" / "model_set.json").read_text())
    stage = made["stages"]["grasp"]
    assert made["wall_time_s"] == pytest.approx(stage["dagger_wall_time_s"] + stage["ship_and_evaluate_s"], abs=0.2)
    assert made["machine_time_s"] > made["wall_time_s"] + first["wall_time_s"] * 0.5


def test_a_made_stage_is_evaluated_again_as_it_is(tmp_path, capsys):
    import hashlib

    recipe = _recipe(tmp_path)
    runs = ["--robot", "fr3", "--recipe", str(recipe), "--models-dir", str(tmp_path / "models"),
            "--run-root", str(tmp_path / "runs")]
    assert make_models.main(runs + ["--evaluate-again", "grasp"]) == 2  # nothing made yet
    assert "is not made" in capsys.readouterr().err
    assert _make(tmp_path, recipe) == 0
    model_dir = tmp_path / "models" / "grasp"
    made = {name: hashlib.sha256((model_dir / name).read_bytes()).hexdigest() for name in ("model.zip", "model.onnx")}
    first_set = json.loads((tmp_path / "models" / "model_set.json").read_text())
    (model_dir / "eval.json").unlink()
    assert make_models.main(runs + ["--evaluate-again", "grasp"]) == 0
    assert "resuming" not in capsys.readouterr().out  # no training
    assert {name: hashlib.sha256((model_dir / name).read_bytes()).hexdigest() for name in made} == made
    plain = json.loads((model_dir / "eval.json").read_text())  # written again
    assert plain["episodes"] == 2
    card = (model_dir / "README.md").read_text()
    assert "Evaluated again on" in card and f"({plain['successes']}/2;" in card
    again = json.loads((tmp_path / "models" / "model_set.json").read_text())
    stage = again["stages"]["grasp"]
    assert stage["evaluated_again"]["evaluate_s"] > 0
    assert again["wall_time_s"] == first_set["wall_time_s"]  # the set's own time is its making
    assert make_models.main(runs + ["--evaluate-again", "grasp", "--remake", "grasp"]) == 2
    # A stage left out of --stages would be judged again and its card never written: refused.
    with pytest.raises(ConfigError, match="--stages leaves it out"):
        ModelSet("fr3", load_recipe(), stages=["reach"], evaluate_again=["place"])


def _shipped_arm_models():
    from fr5_rl.config import package_root

    return sorted(path for path in (package_root() / "models").glob("fr*/*") if (path / "meta.json").is_file())


@pytest.mark.parametrize("model_dir", _shipped_arm_models(), ids=lambda path: f"{path.parent.name}/{path.name}")
def test_each_shipped_arm_model_is_its_directorys_arm_and_its_card_says_its_figures(model_dir):
    from fr5_rl.deploy.bundle import ModelFilesError

    policy = load_policy(model_dir, "onnx")
    assert policy.meta["robot"] == model_dir.parent.name
    assert policy.task == {stage.name: stage.task for stage in load_recipe().stages}[model_dir.name]
    with pytest.raises(ModelFilesError, match="not the fr5"):
        load_policy(model_dir, "onnx", expected_robot="fr5")
    card = (model_dir / "README.md").read_text()
    for name in ("eval.json", "eval_perturbed.json"):
        figures = json.loads((model_dir / name).read_text())
        assert f"({figures['successes']}/{figures['episodes']};" in card
    assert (model_dir / "model.zip").stat().st_size + (model_dir / "model.onnx").stat().st_size < 10e6
