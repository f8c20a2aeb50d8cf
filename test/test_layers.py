"""The package's layers run one way: ros -> deploy/perception/drivers/sim -> shared -> config,
and the training side builds on deploy, never the other way. Checked on the import graph that the
source itself declares (every `import` and `from ... import`, at any depth of a function)."""
import ast
from pathlib import Path
from typing import Dict, Set

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "src" / "fr5_rl"


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports_of(path: Path) -> Set[str]:
    """Modules of fr5_rl that ``path`` imports (resolved relative imports included)."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            found.add(target)
            # `from . import x` / `from ..deploy import bundle` name submodules.
            found.update(f"{target}.{alias.name}" for alias in node.names)
    modules = {module_name(p) for p in PACKAGE.rglob("*.py")}
    return {module for module in found if module in modules and module != name}


def import_graph() -> Dict[str, Set[str]]:
    return {module_name(path): imports_of(path) for path in PACKAGE.rglob("*.py")}


def layer(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "fr5_rl"


GRAPH = import_graph()
# Which layers each layer may import. Anything not listed (config, kinematics, observation,
# control, transforms: the shared layer) imports only the shared layer.
ALLOWED = {
    # The simulator node runs an episode (plant, chain, task), not the gym environment.
    "ros": {"ros", "deploy", "perception", "drivers", "shared", "episode", "episode_runner", "scene_episodes", "sim",
            "tasks"},
    "cli": {"training", "deploy", "shared", "envs", "expert", "sim", "tasks", "cli", "sim_to_real"},
    # Record, replay, compare and fit (compare_run.py, fit_driver.py): tools, never deployed.
    "sim_to_real": {"sim_to_real", "shared", "episode", "sim", "tasks"},
    "training": {"training", "deploy", "shared", "envs", "goal_env", "expert", "sim", "tasks"},
    # The rehearsal's chain in one process: the simulator (its world built as the node builds
    # it), the drivers and the deployed node's code.
    "chain_emulation": {"shared", "episode", "episode_runner", "scene_episodes", "sim", "tasks", "deploy", "drivers"},
    "deploy": {"deploy", "shared"},
    "perception": {"perception", "shared"},
    "drivers": {"drivers", "shared"},
    # The simulator node's episodes without ROS: phases, commands, records.
    "episode_runner": {"shared", "episode", "scene_episodes", "sim", "tasks"},
    # Clearing a table in the simulator: a scene's objects, one episode each.
    "scene_episodes": {"shared", "episode", "tasks"},
    # The place task in the goal-conditioned API (HER), around the gym environment.
    "goal_env": {"shared", "envs"},
    # gymnasium's API around one episode.
    "envs": {"shared", "episode", "tasks"},
    # One episode: the plant (sim), the control chain, the task.
    "episode": {"shared", "sim", "tasks", "control_chain"},
    # Between the policy's action and the plant: the chain's timing, bridge, guard and camera.
    "control_chain": {"shared", "sim"},
    "expert": {"shared", "envs", "sim", "tasks"},
    # The simulator emulates a cell's hardware around the drivers' own code (the gripper chain).
    "sim": {"shared", "sim", "drivers"},
    "tasks": {"shared", "tasks"},
    "shared": {"shared"},
}
SHARED = {"config", "env_config", "kinematics", "observation", "control", "transforms", "gripper", "motion_guard",
          "help_text", "draws", "objects", "scenes", "clearing", "fr5_rl"}


def kind(module: str) -> str:
    name = layer(module)
    return "shared" if name in SHARED else name


@pytest.mark.parametrize("module", sorted(GRAPH))
def test_imports_run_down_the_layers(module):
    wrong = sorted(target for target in GRAPH[module] if kind(target) not in ALLOWED[kind(module)])
    assert not wrong, f"{module} ({kind(module)}) imports {wrong}, which its layer must not depend on"


def test_nothing_deployed_imports_training():
    for module, targets in GRAPH.items():
        if kind(module) in ("ros", "deploy", "perception", "drivers"):
            assert not any(kind(t) in ("training", "cli") for t in targets), (module, targets)


def test_the_import_graph_has_no_cycle():
    # Package __init__ modules only register envs: they are not part of the layering.
    graph = {m: {t for t in ts if not t.endswith("__init__") and t != "fr5_rl"} for m, ts in GRAPH.items()}
    state: Dict[str, int] = {}

    def visit(node, trail):
        state[node] = 1
        for target in graph.get(node, ()):
            if state.get(target) == 1:
                pytest.fail(" -> ".join(trail + [node, target]))
            if not state.get(target):
                visit(target, trail + [node])
        state[node] = 2

    for module in graph:
        if not state.get(module):
            visit(module, [])


def test_the_checker_sees_relative_and_nested_imports():
    """The graph is built right: known edges of the source appear in it."""
    assert "fr5_rl.deploy.bundle" in GRAPH["fr5_rl.deploy.policy"]
    assert "fr5_rl.deploy.deployment" in GRAPH["fr5_rl.ros.policy_node"]
    assert "fr5_rl.training.train" in GRAPH["fr5_rl.cli.train"]  # imported inside main()


def test_only_sim_calls_pybullet():
    for path in PACKAGE.rglob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        names = {alias.name for node in ast.walk(tree) if isinstance(node, ast.Import) for alias in node.names}
        names |= {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom) and node.module}
        if any(name == "pybullet" or name.startswith("pybullet") for name in names):
            assert kind(module_name(path)) == "sim", f"{path.relative_to(ROOT)} imports pybullet; only sim/ may"
