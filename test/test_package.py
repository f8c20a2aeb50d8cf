"""The catkin package itself: catkin_lint is clean, launch files parse, entry points are thin,
and nothing tracked holds a machine-specific absolute path."""
import re
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
# catkin_lint, ruff, roslaunch's loader, rosrun, the package's files: `make lint` and `make test`.
pytestmark = pytest.mark.integration


def test_catkin_lint_reports_no_problems():
    result = subprocess.run(["catkin_lint", "-W1", str(ROOT)], capture_output=True, text=True, timeout=120)
    output = result.stdout + result.stderr
    assert "found 0 problems" in output or "checked 1 packages and found 0" in output, output


def test_ruff_reports_no_findings():
    """`make lint`'s second half, with the rules of ruff.toml."""
    result = subprocess.run(["ruff", "check", str(ROOT)], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert result.returncode == 0, result.stdout + result.stderr


@pytest.mark.parametrize("launch", sorted((ROOT / "launch").glob("*.launch")), ids=lambda p: p.name)
def test_launch_file_parses_with_roslaunch(launch):
    # roslaunch's own loader: substitution args, includes, rosparam files must all resolve.
    import roslaunch.config
    import roslaunch.xmlloader

    config = roslaunch.config.ROSLaunchConfig()
    roslaunch.xmlloader.XmlLoader().load(str(launch), config, verbose=False)
    assert config.nodes, f"{launch.name} starts no node"


def test_the_vision_launch_arguments_set_the_cameras_parameters():
    """``camera_profile`` loads config/camera_<profile>.yaml over camera.yaml; ``camera_rate``
    overrides whichever rate that leaves (as a float, the node's type)."""
    import roslaunch.config
    import roslaunch.xmlloader

    def camera_params(*args):
        config = roslaunch.config.ROSLaunchConfig()
        loader = roslaunch.xmlloader.XmlLoader()
        loader.load(str(ROOT / "launch" / "sim_policy.launch"), config, verbose=False,
                    argv=["sim_policy.launch", "vision:=true", "rviz:=false", *args])
        return {key.rsplit("/", 1)[1]: param.value for key, param in config.params.items() if key.startswith("/camera/")}

    assert (camera_params()["width"], camera_params()["rate"]) == (640, 15.0)
    profile = camera_params("camera_profile:=320x240")
    assert (profile["width"], profile["renderer"], profile["rate"]) == (320, "tiny", 15.0)
    slower = camera_params("camera_profile:=320x240", "camera_rate:=10")
    assert slower["width"] == 320 and slower["rate"] == 10.0 and isinstance(slower["rate"], float)


@pytest.mark.parametrize("driver", ["default", "fairino"])
def test_vision_target_truth_moves_the_detector_off_the_policys_target(driver):
    """``vision_target:=truth``: the simulator publishes the true pose on the policy's target
    topic and the detector publishes elsewhere, on either driver; the default leaves the detector
    alone on it; anything else is refused."""
    import roslaunch.config
    import roslaunch.core
    import roslaunch.xmlloader

    def params(*args):
        config = roslaunch.config.ROSLaunchConfig()
        roslaunch.xmlloader.XmlLoader().load(str(ROOT / "launch" / "sim_policy.launch"), config, verbose=False,
                                             argv=["sim_policy.launch", "vision:=true", "rviz:=false",
                                                   f"driver:={driver}", *args])
        return {key: param.value for key, param in config.params.items()}

    detector = params()
    policy_target = detector["/fr5_policy/target_topic"]
    assert detector["/detector/target_topic"] == policy_target and detector["/fr5_sim/publish_target"] is False
    truth = params("vision_target:=truth")
    assert truth["/fr5_policy/target_topic"] == truth["/fr5_sim/target_topic"] == policy_target
    assert truth["/fr5_sim/publish_target"] is True
    assert truth["/detector/target_topic"] not in (policy_target, "")
    with pytest.raises(roslaunch.core.RLException, match="vision_target_must_be_detector_or_truth"):
        params("vision_target:=camera")


@pytest.mark.parametrize("driver", ["default", "fairino"])
def test_with_vision_the_policy_node_takes_policy_node_vision_yaml(driver):
    """vision:=true gives the policy node config/policy_node_vision.yaml over policy_node.yaml (the
    emulated chain's --target camera reads the same file): the rise clear of a target gone stale,
    and the target timeout, which sim_policy.launch's vision_target_timeout (the detector's
    max_image_age too) must equal; without vision, policy_node.yaml's hold in place."""
    import roslaunch.config
    import roslaunch.xmlloader

    from fr5_rl.config import load_yaml

    def policy_params(*args):
        config = roslaunch.config.ROSLaunchConfig()
        roslaunch.xmlloader.XmlLoader().load(str(ROOT / "launch" / "sim_policy.launch"), config, verbose=False,
                                             argv=["sim_policy.launch", "rviz:=false", f"driver:={driver}", *args])
        return {key.rsplit("/", 1)[1]: param.value for key, param in config.params.items()
                if key.startswith("/fr5_policy/")}

    vision, plain = load_yaml("policy_node_vision"), load_yaml("policy_node")
    assert vision["stale_target_rise"] > 0.0 == plain["stale_target_rise"]
    seen = policy_params("vision:=true")
    assert seen["stale_target_rise"] == vision["stale_target_rise"]
    assert seen["target_timeout"] == vision["target_timeout"]
    assert policy_params()["stale_target_rise"] == 0.0


def test_every_script_is_a_thin_installed_entry_point():
    cmake = (ROOT / "CMakeLists.txt").read_text()
    for script in sorted((ROOT / "scripts").glob("*.py")):
        text = script.read_text()
        assert script.stat().st_mode & 0o111, f"{script.name} is not executable"
        assert text.startswith("#!/usr/bin/env python3"), script.name
        assert re.search(r"from fr5_rl\.[\w.]+ import main", text), f"{script.name} should only call fr5_rl's main()"
        assert len(text.splitlines()) < 15, f"{script.name} holds logic; move it into src/fr5_rl"
        assert f"scripts/{script.name}" in cmake, f"{script.name} missing from catkin_install_python()"


def imported_top_level_modules(paths) -> set:
    """Top-level names of every absolute import in ``paths`` (at any depth of a function)."""
    import ast

    names = set()
    for path in paths:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                names.update(alias.name.split(".")[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
                names.add(node.module.split(".")[0])
    return names


def is_ros_package(name: str) -> bool:
    """rospkg knows it, or it is a message/service package (Debian installs those as plain
    Python modules that rospkg does not list)."""
    import importlib.util

    import rospkg

    if name in ROS_PACKAGES.setdefault("known", set(rospkg.RosPack().list())):
        return True
    try:
        return any(importlib.util.find_spec(f"{name}.{kind}") is not None for kind in ("msg", "srv"))
    except (ImportError, ValueError):
        return False


ROS_PACKAGES: dict = {}


def ros_packages_imported_or_launched(paths, launch_files) -> set:
    """The ROS packages among the imports of ``paths`` and the ``pkg=`` of ``launch_files``."""
    launched = {match for launch in launch_files
                for match in re.findall(r'pkg="([^"$]+)"', launch.read_text(encoding="utf-8"))}
    return {name for name in imported_top_level_modules(paths) | launched if is_ros_package(name)} - {"fr5_rl"}


def package_xml_depends(*kinds: str) -> set:
    return {e.text for e in ET.parse(ROOT / "package.xml").getroot() if e.tag in kinds}


def test_package_xml_declares_every_ros_package_the_code_and_launch_files_use():
    """Derived from the source, not a list written here: every ROS package a node, library
    module or launch file uses is an exec_depend; every one the rostests add is a test_depend."""
    runtime = ros_packages_imported_or_launched(
        list((ROOT / "src").rglob("*.py")) + list((ROOT / "scripts").glob("*.py")),
        list((ROOT / "launch").glob("*.launch")))
    assert {"rospy", "tf2_ros", "sensor_msgs", "rosgraph_msgs", "robot_state_publisher", "rviz"} <= runtime  # seen
    missing = sorted(runtime - package_xml_depends("exec_depend", "depend"))
    assert not missing, f"package.xml lacks <exec_depend> for {missing}"
    tests = ros_packages_imported_or_launched(list((ROOT / "test").rglob("*.py")),
                                              list((ROOT / "test" / "rostest").glob("*.test")))
    missing = sorted(tests - runtime - package_xml_depends("exec_depend", "depend", "test_depend"))
    assert not missing, f"package.xml lacks <test_depend> for {missing}"


def test_every_third_party_import_is_pinned_in_requirements():
    """A module that is neither the standard library, ROS, nor fr5_rl comes from a distribution
    named in requirements.txt (a fresh machine gets nothing else)."""
    import importlib.metadata
    import sys

    requirements = {re.split(r"[<>=;\[ ]", line.strip())[0].lower().replace("_", "-")
                    for line in (ROOT / "requirements.txt").read_text().splitlines()
                    if line.strip() and not line.startswith("#")}
    distributions = importlib.metadata.packages_distributions()
    ros = {"rosgraph", "rosbag", "roslib", "rospkg", "genpy", "tf2_py", "catkin_pkg"}  # ROS's own Python tools
    paths = list((ROOT / "src").rglob("*.py")) + list((ROOT / "tools").rglob("*.py"))
    unpinned = {}
    for module in sorted(imported_top_level_modules(paths)):
        if module in sys.stdlib_module_names or module in ros or is_ros_package(module) or module == "fr5_rl" \
                or any((folder / f"{module}.py").is_file() for folder in (ROOT / "tools", ROOT / "tools" / "bench")):
            continue
        names = {name.lower().replace("_", "-") for name in distributions.get(module, [module])}
        if not names & requirements:
            unpinned[module] = sorted(names)
    assert not unpinned, f"imports without a pin in requirements.txt: {unpinned}"


def test_no_machine_specific_absolute_paths_in_tracked_files():
    files = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True).stdout.split()
    # Assembled from pieces so that this file does not match itself.
    roots = ("work", "root", "farm")
    pattern = re.compile("|".join("/" + root + "/" for root in roots) + "|/home/[a-z]+/")
    offenders = []
    for name in files:
        path = ROOT / name
        if path.suffix in (".md", ".stl", ".png", ".zip", ".pkl", ".onnx", ".gz") or not path.is_file():
            continue
        try:
            if pattern.search(path.read_text(encoding="utf-8")):
                offenders.append(name)
        except UnicodeDecodeError:
            continue
    assert offenders == []


# ----------------------------------------------------------------------------- the front door
SCRIPTS = sorted(path.name for path in (ROOT / "scripts").glob("*.py"))


@pytest.mark.slow  # rosrun searches the workspace for each script
@pytest.mark.parametrize("script", SCRIPTS)
def test_rosrun_finds_each_script_exactly_once(script):
    """`rosrun fr5_rl <script> --help` as a new user types it: a real shell that sources env.sh,
    stdin closed (rosrun's "pick one of the following" menu would read it), no file-system loop."""
    command = f"source '{ROOT / 'env.sh'}' && rosrun fr5_rl {script} --help"
    result = subprocess.run(["bash", "-c", command], stdin=subprocess.DEVNULL, capture_output=True, text=True,
                            timeout=120, cwd="/")
    assert result.returncode == 0, result.stdout + result.stderr
    assert result.stdout.startswith("usage:") and script in result.stdout.splitlines()[0], result.stdout
    for symptom in ("non-unique", "File system loop", "Couldn't find"):
        assert symptom not in result.stdout + result.stderr, result.stdout + result.stderr


def test_catkin_workspace_is_outside_the_package():
    """rosrun searches the package directory with `find -L`: a workspace inside it holds a
    second copy of every script (devel/) and a link back to the package (a loop)."""
    result = subprocess.run(["bash", "-c", f"source '{ROOT / 'env.sh'}' && echo $FR5_RL_WORKSPACE && rospack find fr5_rl"],
                            capture_output=True, text=True, timeout=60)
    workspace, package = result.stdout.split()
    assert Path(package).resolve() == ROOT
    assert ROOT not in Path(workspace).resolve().parents and Path(workspace).resolve() != ROOT
    assert not (ROOT / ".catkin_ws").exists()
