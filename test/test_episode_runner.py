"""The simulator node's episodes without ROS (fr5_rl.episode_runner): the phases, what a command
does in each, the records. The clock is injected; the episode is the real one (PyBullet)."""
import numpy as np
import pytest

from fr5_rl.episode import Episode
from fr5_rl.episode_runner import EpisodeRunner, Phase
from fr5_rl.sim.servo import DriverModel
from fr5_rl.tasks import EpisodeVerdict


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture(scope="module")
def sim():
    episode = Episode.build("reach")
    yield episode
    episode.close()


def runner_for(sim, go_to_start=False, hold=0.5, servo_rate=0.0):
    clock = Clock()
    driver = DriverModel(servo_rate, 0, [], sim.physics_dt, sim.robot_spec.home_joint_positions)
    return EpisodeRunner(sim, driver, seed=4000, go_to_start=go_to_start, hold_after_episode=hold, clock=clock), clock


def verdict(success=True):
    return EpisodeVerdict(success, None if success else "timeout", success, not success, 7, None)


def test_an_episode_goes_through_its_phases_and_is_recorded(sim):
    runner, clock = runner_for(sim)
    runner.place_next(settle=0.3)
    assert runner.phase is Phase.SETTLING and runner.holding and not runner.hold_is_over()
    assert not runner.take_arm_command([0.0] * 6, None)  # the new scene stands: dropped
    assert not runner.take_gripper_command(0.01, None)
    clock.now += 0.3
    assert runner.hold_is_over()
    runner.begin(positioning=False)
    assert runner.phase is Phase.WAITING and not runner.commanded and not runner.judged
    command = sim.joint_positions() + 0.01
    assert runner.take_arm_command(command, None)
    assert runner.phase is Phase.RUNNING and runner.judged
    assert runner.arm_command == pytest.approx(tuple(command))
    record = runner.finish(verdict(), sim_time=1.5, lockstep=True)
    start = sim.object_start
    assert record == {"episode": 1, "seed": 4000, "success": True, "failure": "", "steps": 7, "sim_time": 1.5,
                      "late_periods": 0, "object": "cylinder",
                      "object_x": round(float(start[0]), 4), "object_y": round(float(start[1]), 4)}
    assert runner.phase is Phase.HOLDING and runner.hold_until == pytest.approx(clock.now + 0.5)
    assert not runner.take_arm_command(command, None)
    runner.place_next()
    runner.finish(verdict(False), sim_time=3.0, lockstep=False)
    assert runner.results == [True, False] and runner.episode == 2


def test_each_episode_is_its_seeds_gym_episode(sim):
    runner, _ = runner_for(sim)
    runner.place_next()
    first = sim.object_pose().position
    runner.finish(verdict(), 0.0, lockstep=False)
    runner.place_next()
    second = sim.object_pose().position
    sim.start(4000)
    assert sim.object_pose().position == first
    sim.start(4001)
    assert sim.object_pose().position == second != first


def test_after_a_teleport_the_arm_waits_for_the_policy_but_the_gripper_does_not(sim):
    runner, _ = runner_for(sim, go_to_start=False)
    runner.place_next()
    start = runner.begin(positioning=True)
    assert runner.phase is Phase.POSITIONING
    assert not runner.take_arm_command(sim.joint_positions(), None)
    assert runner.take_gripper_command(0.02, None) and runner.gripper_target == 0.02
    runner.positioned(start - 1)  # an older start's answer: not this one's
    assert runner.phase is Phase.POSITIONING
    runner.positioned(start)
    assert runner.phase is Phase.WAITING


def test_a_start_move_is_obeyed_but_not_timed(sim):
    runner, _ = runner_for(sim, go_to_start=True)
    runner.place_next()
    start = runner.begin(positioning=True)
    assert runner.take_arm_command(sim.joint_positions(), None)
    assert runner.phase is Phase.POSITIONING and not runner.commanded  # the start move is not judged
    runner.positioned(start)
    runner.take_arm_command(sim.joint_positions(), None)
    assert runner.phase is Phase.RUNNING


def test_go_to_start_places_only_the_object_after_the_first_episode(sim):
    runner, _ = runner_for(sim, go_to_start=True)
    assert not runner.next_start_keeps_the_arm
    runner.place_next()
    moved = sim.joint_positions() + np.array([0.3, -0.2, 0.2, 0.0, 0.1, 0.0])
    sim.plant.reset_arm(moved, sim.robot_spec.max_opening_width)
    runner.finish(verdict(), 0.0, lockstep=False)
    assert runner.next_start_keeps_the_arm
    runner.place_next()
    np.testing.assert_allclose(sim.joint_positions(), moved, atol=1e-9)
    teleporting, _ = runner_for(sim, go_to_start=False)
    teleporting.episode = 1
    teleporting.place_next()
    assert np.abs(sim.joint_positions() - moved).max() > 0.05


def test_a_calibration_obeys_commands_and_judges_nothing(sim):
    runner, _ = runner_for(sim)
    runner.place_next()
    runner.begin(positioning=False)
    assert runner.calibrate(True, (0.0, 0.0, 0.0))
    assert runner.phase is Phase.CALIBRATING and not runner.judged
    assert runner.gripper_target == pytest.approx(sim.scene().object_size[0])  # closed on the object
    assert runner.take_arm_command(sim.joint_positions(), None) and runner.phase is Phase.CALIBRATING
    assert not runner.calibrate(True, (0.0, 0.0, 0.0))  # already on
    assert runner.calibrate(False, (0.0, 0.0, 0.0)) and runner.phase is Phase.HOLDING
    assert not runner.calibrate(False, (0.0, 0.0, 0.0))


def test_a_real_time_command_acts_from_the_first_step_after_it_arrived(sim):
    runner, clock = runner_for(sim)
    runner.place_next()
    runner.begin(positioning=False)
    home = tuple(sim.joint_positions())
    target = tuple(np.asarray(home) + np.array([0.2, 0, 0, 0, 0, 0]))
    runner.take_arm_command(target, arrived=10.0)
    runner.take_gripper_command(0.0, arrived=10.0)
    runner.physics_step(step_start=9.99)  # the step began before the command arrived
    assert runner.arm_command is None and runner.gripper_target == sim.robot_spec.max_opening_width
    runner.physics_step(step_start=10.0)
    assert runner.arm_command == target and runner.gripper_target == 0.0
    assert runner.driver.response.applied == pytest.approx(list(target))  # no lag configured: the targets as they are
