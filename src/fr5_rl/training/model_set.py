"""One arm's whole model set from one command: what ``make models ROBOT=fr10`` runs.

A recipe (``config/recipes/model_set.yaml``) lists stages (reach, grasp, place); each is DAgger
from the scripted expert (:mod:`fr5_rl.training.imitation`) in the arm's own cell. Each stage's
model is then shipped (``models/<arm>/<stage>/``: the model, its statistics, ``meta.json``,
``model.onnx`` checked against the torch model), evaluated on held-out placements in every
condition of the recipe, and described by a card (``README.md``) with its figures. The whole set
ends with ``models/<arm>/model_set.json``.

A killed run resumes where it stopped: a stage whose card is written is kept, a stage whose
DAgger run finished is shipped and evaluated, and a DAgger run that had begun continues from the
last round it finished (:class:`fr5_rl.training.imitation.DaggerCheckpoint`). Progress and each
step's wall time are kept in ``<run root>/progress.json``.
"""
from __future__ import annotations

import dataclasses
import json
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional

from ..config import ConfigError, check_robot_name, deep_update, load_typed, package_root
from ..deploy.bundle import (EVAL_FILE, META_FILE, MODEL_FILE, STATS_FILE, machine_description, read_meta,
                             write_json_atomic)
from ..env_config import TASK_NAMES
from .hyperparameters import hyperparameter_path

RECIPE = "recipes/model_set.yaml"
PROGRESS_FILE = "progress.json"
SET_FILE = "model_set.json"
PARITY_OBSERVATIONS = 1000


@dataclass(frozen=True)
class Stage:
    """One model of the set.

    :param name: the model directory's name under ``models/<arm>/``.
    :param task: the task it is trained and judged on.
    :param hyperparams: the DAgger file (a name in ``config/`` or ``config/recipes/``).
    :param rounds: DAgger rounds after the expert's.
    :param episodes: episodes rolled out per round; None: the DAgger file's.
    :param epochs: fitting epochs per round; None: the DAgger file's.
    """

    name: str
    task: str
    hyperparams: str
    rounds: int
    episodes: Optional[int] = None
    epochs: Optional[int] = None

    def check(self, source: str) -> None:
        if self.task not in TASK_NAMES:
            raise ConfigError(f"{source}: stage '{self.name}': task '{self.task}' is not one of {', '.join(TASK_NAMES)}")
        if self.rounds < 1:
            raise ConfigError(f"{source}: stage '{self.name}': rounds must be at least 1, got {self.rounds}")
        hyperparameter_path(self.hyperparams)  # raises with the places it looked in


@dataclass(frozen=True)
class Evaluation:
    """How each model is judged: ``episodes`` held-out placements from ``seed_start`` in each
    condition (environment overrides over the model's own observation and action), what each
    condition is in words (for the cards), and the success each task must reach in a condition
    (``targets[task][condition]``)."""

    episodes: int
    seed_start: int
    conditions: Dict[str, Dict[str, Any]]
    descriptions: Dict[str, str] = field(default_factory=dict)
    targets: Dict[str, Dict[str, float]] = field(default_factory=dict)

    def check(self, source: str) -> None:
        if self.episodes < 1:
            raise ConfigError(f"{source}: evaluation.episodes must be at least 1, got {self.episodes}")
        for name in self.descriptions:
            if name not in self.conditions:
                raise ConfigError(f"{source}: evaluation.descriptions names condition '{name}', "
                                  f"not one of {', '.join(self.conditions)}")
        for task, by_condition in self.targets.items():
            unknown = [name for name in by_condition if name not in self.conditions]
            if unknown:
                raise ConfigError(f"{source}: evaluation.targets.{task} names condition '{unknown[0]}', "
                                  f"not one of {', '.join(self.conditions)}")


@dataclass(frozen=True)
class ModelSetRecipe:
    """``config/recipes/model_set.yaml``."""

    seed: int
    workers: int
    stages: List[Stage]
    evaluation: Evaluation

    def check(self, source: str) -> None:
        names = [stage.name for stage in self.stages]
        if len(set(names)) != len(names):
            raise ConfigError(f"{source}: stage names must differ, got {names}")
        if self.workers < 1:
            raise ConfigError(f"{source}: workers must be at least 1, got {self.workers}")


def load_recipe(path_or_name: str | Path = RECIPE) -> ModelSetRecipe:
    """The recipe file, checked.

    :raises ConfigError: a malformed recipe; the message names the key.
    """
    return load_typed(ModelSetRecipe, path_or_name)


def _evaluate_condition(model_dir: str, condition: Dict[str, Any], seeds: List[int]) -> List[Dict[str, Any]]:
    """One condition's episodes of one model (in a worker process)."""
    import torch

    from ..deploy.policy import load_policy
    from .evaluation import run_episodes

    torch.set_num_threads(1)
    policy = load_policy(Path(model_dir), "torch")
    overrides = deep_update(policy.deployment_overrides(), condition, strict=False)
    return run_episodes(policy.task, overrides, lambda env: (policy.act, None), seeds)


class ModelSet:
    """Make, ship, evaluate and describe one arm's models.

    :param robot: the arm (``config/robots/<robot>.yaml``).
    :param recipe: the recipe; default ``config/recipes/model_set.yaml``.
    :param models_dir: where the models go; default ``models/<robot>`` in the package.
    :param run_root: where the training runs and ``progress.json`` go; default ``runs/models_<robot>``
        in the current directory.
    :param stages: only these stages (names), in the recipe's order; default all.
    :param remake: stages to make again from nothing: their run and their record are discarded.
    :param evaluate_again: made stages whose shipped model is evaluated again, as it is (after a
        change to the simulator), and whose card is written again with the new figures.
    :param recipe_name: what the models' ``meta.json`` and cards name as their recipe (the file
        ``recipe`` was read from); default the shipped one's.
    """

    def __init__(self, robot: str, recipe: Optional[ModelSetRecipe] = None, models_dir: Optional[Path] = None,
                 run_root: Optional[Path] = None, stages: Optional[List[str]] = None,
                 remake: Optional[List[str]] = None, recipe_name: Optional[str] = None,
                 evaluate_again: Optional[List[str]] = None) -> None:
        self.robot = check_robot_name(robot)
        self.recipe = recipe or load_recipe()
        self.models_dir = Path(models_dir) if models_dir else package_root() / "models" / self.robot
        self.run_root = Path(run_root) if run_root else Path("runs") / f"models_{self.robot}"
        known = [stage.name for stage in self.recipe.stages]
        unknown = [name for name in list(stages or []) + list(remake or []) + list(evaluate_again or [])
                   if name not in known]
        if unknown:
            raise ConfigError(f"no stage '{unknown[0]}' in the recipe; its stages: {', '.join(known)}")
        self.stages = [stage for stage in self.recipe.stages if stages is None or stage.name in stages]
        self.progress_path = self.run_root / PROGRESS_FILE
        self.remake = list(remake or [])
        self.evaluate_again = list(evaluate_again or [])
        both = sorted(set(self.remake) & set(self.evaluate_again))
        if both:
            raise ConfigError(f"stage '{both[0]}' is both to be made again and evaluated again: choose one")
        left_out = [name for name in self.evaluate_again if name not in [stage.name for stage in self.stages]]
        if left_out:
            raise ConfigError(f"stage '{left_out[0]}' is to be evaluated again but --stages leaves it out: "
                              "name it in --stages too")
        self.recipe_name = recipe_name or f"config/{RECIPE}"

    # -- progress ------------------------------------------------------------------------------
    def _read_progress(self) -> Dict[str, Any]:
        if self.progress_path.is_file():
            progress = json.loads(self.progress_path.read_text())
            if progress.get("robot") != self.robot:
                raise ConfigError(f"{self.progress_path} belongs to the {progress.get('robot')}'s model set; "
                                  f"give this arm its own --run-root")
            return progress
        return {"robot": self.robot, "stages": {}, "wall_time_s": 0.0}

    def _write_progress(self, progress: Dict[str, Any]) -> None:
        self.run_root.mkdir(parents=True, exist_ok=True)
        write_json_atomic(self.progress_path, progress)

    # -- the steps of one stage ----------------------------------------------------------------
    def _train(self, stage: Stage) -> Path:
        """DAgger for ``stage``, resumed if it had begun; returns its run directory."""
        from .imitation import DaggerCheckpoint, run_dagger
        from .run_settings import DaggerRun

        run_dir = self.run_root / stage.name
        resume = DaggerCheckpoint(run_dir).exists()
        run_dagger(DaggerRun(task=stage.task, hyperparams=stage.hyperparams, run_dir=run_dir, seed=self.recipe.seed,
                             rounds=stage.rounds, episodes=stage.episodes, epochs=stage.epochs, robot=self.robot,
                             workers=self.recipe.workers, resume=resume))
        return run_dir

    def _ship(self, stage: Stage, run_dir: Path) -> Path:
        """The run's last round into ``models/<arm>/<stage>/`` with its ONNX export, checked.

        The last, not the round DAgger judged best: each round's judgement is 50 episodes (a
        90 % learner scores 82–96 % by chance), while the data set only grows. On the FR10's place
        stage the last of 14 rounds did 94.5 % perturbed over 200 held-out episodes, the round
        judged best (11) 94.0 %, and 188 against 180 of 200 plain.
        """
        from .onnx_export import PARITY_TOLERANCE, export, parity

        source = run_dir / "final"
        target = self.models_dir / stage.name
        target.mkdir(parents=True, exist_ok=True)
        for name in (MODEL_FILE, STATS_FILE):
            shutil.copy2(source / name, target / name)
        summary = json.loads((run_dir / "summary.json").read_text())
        meta = read_meta(source)
        meta.update({"training_method": "dagger", "training_rounds": stage.rounds,
                     "training_wall_time_s": summary["wall_time_s"], "machine": summary["machine"],
                     "source_run": f"{self.run_root.name}/{stage.name}", "recipe": self.recipe_name, "stage": stage.name})
        write_json_atomic(target / META_FILE, meta)
        export(target)
        worst = parity(target, PARITY_OBSERVATIONS)
        if worst > PARITY_TOLERANCE:
            raise RuntimeError(f"{target}: ONNX and SB3 disagree by {worst:.2e} > {PARITY_TOLERANCE:g}; "
                               "re-export with export_onnx.py and check onnxruntime's version")
        return target

    def _evaluate(self, stage: Stage, model_dir: Path) -> Dict[str, Dict[str, Any]]:
        """Every condition of the recipe, in parallel over the workers; each written to
        ``eval.json`` (plain) or ``eval_<condition>.json`` with a CSV beside it."""
        import multiprocessing

        from .evaluation import summarise, write_results

        settings = self.recipe.evaluation
        seeds = list(range(settings.seed_start, settings.seed_start + settings.episodes))
        names = list(settings.conditions)
        t0 = time.time()
        jobs = [(str(model_dir), settings.conditions[name], seeds) for name in names]
        with multiprocessing.get_context("forkserver").Pool(min(self.recipe.workers, len(jobs))) as pool:
            results = pool.starmap(_evaluate_condition, jobs)
        meta = read_meta(model_dir)
        summaries = {}
        for name, records in zip(names, results):
            summary = summarise(records)
            summary.update({"policy": f"models/{self.robot}/{stage.name}", "task": stage.task, "backend": "torch",
                            "deterministic": True, "seeds": [seeds[0], seeds[-1]], "condition": name,
                            "condition_overrides": settings.conditions[name], "robot": self.robot,
                            "algo": meta["algo"], "training_steps": meta.get("num_timesteps"),
                            "training_wall_time_s": meta.get("training_wall_time_s"),
                            "machine": machine_description(), "eval_wall_time_s": round(time.time() - t0, 1)})
            out = model_dir / (EVAL_FILE if name == "plain" else f"eval_{name}.json")
            write_results(summary, records, out, out.with_suffix(".csv"))
            summaries[name] = summary
        return summaries

    # -- the whole set -------------------------------------------------------------------------
    def run(self) -> Dict[str, Any]:
        """Make every stage not yet made; returns the set's summary (also ``models/<arm>/model_set.json``)."""
        progress = self._read_progress()
        began = time.time()
        spent_before = float(progress.get("wall_time_s", 0.0))
        for name in self.remake:
            progress["stages"].pop(name, None)
            shutil.rmtree(self.run_root / name, ignore_errors=True)
        again = [stage for stage in self.stages if stage.name in self.evaluate_again]
        for stage in again:  # every one checked before any is evaluated
            record = progress["stages"].get(stage.name) or {}
            if not record.get("card"):
                raise ConfigError(f"stage '{stage.name}' of the {self.robot}'s set is not made ({self.progress_path} "
                                  "has no card for it): make it, or evaluate a model on its own with evaluate.py")
            if record.get("definition") != dataclasses.asdict(stage):
                raise ConfigError(f"stage '{stage.name}' was made by another definition in the recipe: make it again "
                                  f"with --remake {stage.name}, or restore the recipe")
        for stage in again:
            name, record = stage.name, progress["stages"][stage.name]
            t0 = time.time()
            record["evaluation"] = {condition: _figures(summary)
                                    for condition, summary in self._evaluate(stage, self.models_dir / name).items()}
            # Not part of making the stage: kept apart from ship_and_evaluate_s.
            record["evaluated_again"] = {"date": time.strftime("%Y-%m-%d"), "evaluate_s": round(time.time() - t0, 1)}
            record["card"] = False
            self._save(progress, began, spent_before)
        for stage in self.stages:
            definition = dataclasses.asdict(stage)
            record = progress["stages"].setdefault(stage.name, {"task": stage.task, "definition": definition})
            if record.get("definition") != definition:
                raise ConfigError(f"stage '{stage.name}' was begun with another definition in the recipe "
                                  f"({record.get('definition')}, now {definition}): make it again with "
                                  f"--remake {stage.name}, or restore the recipe")
            if record.get("card"):
                print(f"[{self.robot}] {stage.name}: made before, kept ({self.models_dir / stage.name})")
                continue
            if not record.get("trained"):
                t0 = time.time()
                run_dir = self._train(stage)
                summary = json.loads((run_dir / "summary.json").read_text())
                record.update({"trained": True, "dagger_wall_time_s": summary["wall_time_s"],
                               "samples": summary["history"][-1]["samples"], "history": summary["history"],
                               "rounds": stage.rounds, "train_step_s": round(time.time() - t0, 1)})
                self._save(progress, began, spent_before)
            if not record.get("evaluation"):
                t0 = time.time()
                model_dir = self._ship(stage, self.run_root / stage.name)
                record["evaluation"] = {name: _figures(summary)
                                        for name, summary in self._evaluate(stage, model_dir).items()}
                record["ship_and_evaluate_s"] = round(time.time() - t0, 1)
                self._save(progress, began, spent_before)
            write_card(self.models_dir / stage.name, stage, record, self.recipe, self.recipe_name)
            record["card"] = True
            self._save(progress, began, spent_before)
            figures = ", ".join(f"{name} {value['successes']}/{value['episodes']}"
                                for name, value in record["evaluation"].items())
            print(f"[{self.robot}] {stage.name}: {figures}")
        # The set's time is its kept stages' own; the machine's, every call's, stages made again included.
        result = {"robot": self.robot, "recipe": self.recipe_name,
                  "wall_time_s": round(sum(stage_time_s(record) for record in progress["stages"].values()), 1),
                  "machine_time_s": progress["wall_time_s"], "machine": machine_description(),
                  "stages": {name: record for name, record in progress["stages"].items()}}
        write_json_atomic(self.models_dir / SET_FILE, result)
        return result

    def _save(self, progress: Dict[str, Any], began: float, spent_before: float) -> None:
        progress["wall_time_s"] = round(spent_before + time.time() - began, 1)
        self._write_progress(progress)


def stage_time_s(record: Mapping[str, Any]) -> float:
    """s a made stage took: its DAgger run (over every call, where a killed one was resumed) and its
    shipping and evaluation."""
    return float(record.get("dagger_wall_time_s", 0.0)) + float(record.get("ship_and_evaluate_s", 0.0))


def percent(share: float, digits: int = 1) -> str:
    """``0.955`` as ``95.5 %`` (the project's docs put a space before the sign)."""
    return f"{100 * share:.{digits}f} %"


def _figures(summary: Mapping[str, Any]) -> Dict[str, Any]:
    """What a card and the set's summary keep of an evaluation."""
    return {key: summary[key] for key in ("successes", "episodes", "success_rate", "success_rate_95ci",
                                          "failures", "by_object", "seeds")}


def write_card(model_dir: Path, stage: Stage, record: Mapping[str, Any], recipe: ModelSetRecipe,
               recipe_name: str = f"config/{RECIPE}") -> Path:
    """The model's ``README.md``: what it does, how it was made, its figures against the targets.

    :param recipe_name: the recipe file, as the package's ``config/...`` (a link) or any path.
    """
    meta = read_meta(model_dir)
    robot = meta["robot"]
    hyperparams = hyperparameter_path(stage.hyperparams).resolve().relative_to(package_root().resolve()).as_posix()
    recipe_link = f"[{recipe_name}](../../../{recipe_name})" if recipe_name.startswith("config/") else f"`{recipe_name}`"
    targets = recipe.evaluation.targets.get(stage.task, {})
    # The recipe's order (a record read back from JSON has its keys sorted).
    judged = [name for name in recipe.evaluation.conditions if name in record["evaluation"]]
    rows = []
    for name in judged:
        figures = record["evaluation"][name]
        low, high = figures["success_rate_95ci"]
        kinds = ", ".join(f"{kind} {value['successes']}/{value['episodes']}"
                          for kind, value in figures["by_object"].items())
        target = targets.get(name)
        verdict = "" if target is None else (f"≥ {percent(target, 0)}: **met**" if figures["success_rate"] >= target
                                             else f"≥ {percent(target, 0)}: not met")
        file_name = EVAL_FILE if name == "plain" else f"eval_{name}.json"
        rows.append(f"| {name} ([{file_name}]({file_name})) | **{percent(figures['success_rate'])}** "
                    f"({figures['successes']}/{figures['episodes']}; 95 % CI {percent(low)}–{percent(high)}) | {kinds} | "
                    f"{verdict} |")
    failures = {name: record["evaluation"][name]["failures"] for name in judged if record["evaluation"][name]["failures"]}
    seeds = next(iter(record["evaluation"].values()))["seeds"]
    machine = meta.get("machine") or {}
    lines = [
        f"# models/{robot}/{stage.name}",
        "",
        f"The {stage.task} policy of the **FAIRINO {robot.upper()}**, made by the arm's model-set recipe "
        f"(`make models ROBOT={robot}`, {recipe_link}, stage `{stage.name}`). "
        "Objects of every kind: boxes at any yaw and cylinders, drawn per episode. Actions are steps of the tcp "
        "pointing down, turned into joint increments by the arm's inverse kinematics.",
        "",
        "```bash",
        f"roslaunch fr5_rl sim_policy.launch model:=models/{robot}/{stage.name}",
        f"rosrun fr5_rl evaluate.py models/{robot}/{stage.name} --episodes 200",
        "```",
        "",
        "| | |",
        "|---|---|",
        f"| arm | `{robot}`; loading it as another arm refuses |",
        f"| algorithm | DAgger from the scripted expert ([{hyperparams}](../../../{hyperparams})), "
        f"{stage.rounds} rounds, the last kept; the actor of an SB3 PPO `MlpPolicy` |",
        f"| observation | {meta['observation_size']} values ([docs/environments.md](../../../docs/environments.md)) |",
        f"| action | {meta['action_size']} values: a step of the tcp (`action.space: tcp`) and the gripper width |",
        f"| training | {record['samples']:,} labelled states, {record['dagger_wall_time_s']:.0f} s on "
        f"{machine.get('cores', '?')} cores ({machine.get('cpu', '?')}) |",
        "",
        f"## Evaluation: {seeds[1] - seeds[0] + 1} placements never trained on "
        f"(seeds {seeds[0]:,}–{seeds[1]:,})",
        "",
        "| condition | success | by object | target (issue #55) |",
        "|---|---|---|---|",
        *rows,
    ]
    descriptions = recipe.evaluation.descriptions
    for name in judged:
        if name in descriptions:
            lines += ["", f"`{name}`: {descriptions[name]}"]
    again = record.get("evaluated_again")
    if again:
        lines += ["", f"Evaluated again on {again['date']}, the model as it was made, in the simulator of that day "
                  "(`make_models.py --evaluate-again`); how it learnt, below, is from its making."]
    history = record.get("history") or []
    if history:
        lines += ["", "## How it learnt", "",
                  "Each round's learner on 50 episodes of the task and 50 of the training world (seeds of their own):",
                  "", "| round | labelled states | success, task | success, training world | wall time |",
                  "|---|---|---|---|---|"]
        for entry in history[1:]:
            lines.append(f"| {entry['round']} | {entry['samples']:,} | {percent(entry['eval_success'], 0)} | "
                         f"{percent(entry.get('eval_success_training_env') or 0.0, 0)} | {entry['wall_s']:.0f} s |")
    if failures:
        lines += ["", "Failures: " + "; ".join(f"{name}: " + ", ".join(f"{cause} {count}" for cause, count in
                                                                        sorted(causes.items()))
                                              for name, causes in failures.items()) + "."]
    path = model_dir / "README.md"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path
