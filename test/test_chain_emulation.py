"""The chain emulation (fr5_rl.chain_emulation, which tools/bench/timing.py runs) is wired as the
rehearsal is: the policy observes the fingers only through the gripper bridge's read-back of the emulated controller, the velocities
it observes are estimated (the driver sends 0.0), and an episode after the first begins with
the motion guard's start move from where the previous one ended."""
import argparse

import numpy as np
import pytest

from fr5_rl import chain_emulation
from fr5_rl.config import load_robot_spec, package_root
from fr5_rl.deploy.deployment import DeploymentStep
from fr5_rl.deploy.policy_node_params import load_policy_node_params
from fr5_rl.deploy.policy import load_policy
from fr5_rl.env_config import load_env_config
from fr5_rl.episode import Episode
from fr5_rl.observation import DelayedTarget


def emulation(profile: str, hidden_radius: float = chain_emulation.CAMERA_HIDDEN_RADIUS_M, state_jitter_s: float = 0.0,
              fresh_state_wait_s: float = 0.0, **overrides):
    params = chain_emulation.simulator_profile(profile)
    args = argparse.Namespace(**{"finger_source": None, "velocity_source": None, "episode_start": None,
                                 "target": "simulator", **overrides})
    chain = chain_emulation.Chain.of(params, args)
    policy = load_policy(package_root() / "models" / "reach", "onnx")
    env = Episode.build("reach", overrides={"reach": {"simulation": {"physics_dt": params.physics_dt,
                                                                     "solver_iterations": params.solver_iterations}}})
    node = load_policy_node_params({"guard": {"go_to_start": True}})
    trained = load_env_config(policy.meta.get("env_overrides", {}))
    step = DeploymentStep(policy, load_robot_spec(), trained, node.joint_state_timeout,
                          node.target_timeout, guard=node.guard if chain.episode_start == "go_to_start" else None)
    return chain_emulation.ChainEmulation(env, step, chain, params, 0.002, np.random.default_rng(0),
                                 trained.observation.joint_velocity_source, hidden_radius,
                                 state_jitter_s=state_jitter_s, fresh_state_wait_s=fresh_state_wait_s), env


def test_the_fairino_profile_is_the_rehearsals_chain():
    run, env = emulation("fairino")
    try:
        assert run.chain == chain_emulation.Chain("bridge", "positions", "go_to_start", publish_velocities=False)
        # Reset, activation and its settle ran before the first episode, as the policy node holds
        # on the bridge's fault until then: the first episode starts with a gripper that can act.
        status = run.bridge.status()
        assert status.activated and not status.fault and run.fault is None
        settle = run.bridge.params.reset_settle + run.bridge.params.activation_settle
        assert run.clock.now >= settle
        first = run.run_episode(930_000)
        # Leave the arm far from the start, as an operator might: the next episode must begin
        # with the guard's slow move back, not a teleport.
        run.previous_end = (np.asarray(run.previous_end) + np.array([0.5, 0.0, 0.0, 0.0, 0.0, 0.0])).tolist()
        second = run.run_episode(930_001)
        assert first["start_move_s"] < 0.05 < 0.5 / 0.3 <= second["start_move_s"]
        moves = [args for method, args in run.emulator.requests() if method == "MoveGripper"]
        assert moves, "the bridge never sent MoveGripper to the emulated controller"
        assert run.bridge.status().readings > 10  # the read-back the fingers are observed through
        state = run.reader.reading().value
        # The fingers as the bridge read them back: whole percent of the stroke.
        percent = 100.0 * state.gripper_width / load_robot_spec().max_opening_width
        assert percent == pytest.approx(round(percent), abs=1e-6)
    finally:
        env.close()


def test_the_default_profile_takes_fingers_and_velocities_from_the_driver():
    run, env = emulation("default")
    try:
        assert run.chain == chain_emulation.Chain("driver", "driver", "reset", publish_velocities=True)
        assert run.bridge is None
        record = run.run_episode(930_000)
        assert record["start_move_s"] == 0.0 and record["steps"] > 0
    finally:
        env.close()


def test_the_camera_target_arrives_one_latency_late_stamped_with_its_capture_and_held_while_hidden():
    """--target camera: the node gets the object's position as the camera saw it one latency
    before (stamped with that capture), and while the tcp is within the hidden radius the
    position the object had when last seen."""
    run, env = emulation("fairino", target="camera", hidden_radius=0.0)
    try:
        assert run.chain.target == "camera"
        env.start(930_000)
        period = 1.0 / 15.0
        camera = DelayedTarget(latency=0.1, frame_period=period, phase=0.03)
        start = env.object_pose().position
        readings = []
        for k in range(20):
            if k == 5:  # pushed 5 cm at 0.1 s
                env.plant.place_object((start[0] + 0.05, start[1]), yaw=0.0)
            run.clock.now += 0.02
            readings.append(run._target(camera, 0.02 * k))
        for k, reading in enumerate(readings):
            age = reading.received - reading.stamp  # stamped with the capture of the frame delivered
            assert (age == pytest.approx(0.02 * k) if 0.02 * k < 0.13 else 0.1 - 1e-9 <= age < 0.1 + period)
        seen_x = [r.value[0] - start[0] for r in readings]
        assert max(abs(x) for x in seen_x[:11]) < 1e-3  # not seen before a frame captured after 0.1 s is through
        assert seen_x[-1] == pytest.approx(0.05, abs=1e-3)
        # The tcp within the radius (every distance is, at 10 m): the push stays unseen.
        run.hidden_radius = 10.0
        env.start(930_000)
        camera = DelayedTarget(latency=0.1, frame_period=0.02, phase=0.0)
        readings = []
        for k in range(15):
            if k == 5:
                env.plant.place_object((start[0] + 0.05, start[1]), yaw=0.0)
            run.clock.now += 0.02
            readings.append(run._target(camera, 0.02 * k))
        assert max(abs(r.value[0] - start[0]) for r in readings) < 1e-3
    finally:
        env.close()


def test_compute_latencies_drawn_from_a_measured_record_set_when_each_command_acts():
    """--compute-from: each period's command acts after a latency drawn from the measured ones
    (in whole physics steps); without them, after the fixed --compute-ms."""
    run, env = emulation("default")
    try:
        assert {run._compute_steps() for _ in range(20)} == {run.compute_steps}
        run.compute_samples = np.array([0.0, 0.012, 0.04])
        drawn = {run._compute_steps() for _ in range(200)}
        assert drawn == {0, round(0.012 / run.physics_dt), round(0.04 / run.physics_dt)}
    finally:
        env.close()


@pytest.mark.slow  # hundreds of emulated periods: `make test`, not `make test-fast`
def test_late_joint_states_repeat_in_some_periods_unless_the_node_waits_for_a_new_one():
    """Delivery jitter beside a timer at the driver's own rate hands some periods the state the
    period before used; the node's wait for a new state (policy_node ~fresh_state_wait) ends that."""
    repeated = {}
    for wait_s in (0.0, 0.015):
        # Up to 20 ms late: every phase of the timer against the states meets it.
        run, env = emulation("fairino", state_jitter_s=0.02, fresh_state_wait_s=wait_s)
        try:
            # Each episode draws the timer's and the states' phases: twelve meet enough of them (four
            # gave 0.8 % or 9.6 % by the models' episode lengths, which move the random stream).
            for seed in range(940_000, 940_012):
                run.run_episode(seed)
            assert run.periods > 1000
            repeated[wait_s] = run.repeated_states / run.periods
        finally:
            env.close()
    assert repeated[0.0] > 0.05  # 16.6 % with models/reach of 2026-11
    assert repeated[0.015] < 0.25 * repeated[0.0]  # 2.1 %: states later than the wait still repeat


@pytest.mark.integration
def test_the_timing_bench_runs_and_writes_its_result(tmp_path):
    """tools/bench/timing.py end to end, one episode: the figure and its JSON (with the profile's
    simulator settings) come out."""
    import json
    import subprocess
    import sys

    out = subprocess.run([sys.executable, str(package_root() / "tools" / "bench" / "timing.py"), "--model",
                          "models/reach", "--profile", "fairino", "--episodes", "1", "--seed", "900000",
                          "--results", str(tmp_path), "--name", "one"], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    result = json.loads((tmp_path / "one.json").read_text())
    assert result["episodes"] == 1 and result["simulator"]["servo_rate"] == 125.0


@pytest.mark.parametrize("model", ["grasp_objects", "place"])
def test_a_model_that_observes_the_objects_shape_and_the_goal_runs_through_the_bench(tmp_path, model):
    """The object's yaw, its shape and the goal reach the emulated node as the simulator node's
    topics bring them: without them the node held, and the bench gave up after 120 s."""
    import json
    import subprocess
    import sys

    out = subprocess.run([sys.executable, str(package_root() / "tools" / "bench" / "timing.py"), "--model",
                          f"models/{model}", "--profile", "fairino", "--target", "camera", "--episodes", "1",
                          "--seed", "1660001", "--results", str(tmp_path), "--name", "one"],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    result = json.loads((tmp_path / "one.json").read_text())
    assert result["episodes"] == 1 and result["model"].endswith(model) and len(result["records"]) == 1


def test_the_emulated_world_holds_the_objects_of_its_model():
    """The bench emulates the simulator node, which builds the world of the model it runs: a
    place model's episodes hold its boxes and cylinders, placed as gym's evaluation places them
    on the same seeds (before stop 62 the bench ran every model on the default cup)."""
    from fr5_rl.deploy.bundle import deployment_overrides, read_meta
    from fr5_rl.envs import FR5Env

    meta = read_meta(package_root() / "models" / "place")
    params = chain_emulation.simulator_profile("fairino")
    world = chain_emulation.model_world(meta, params)
    # The node's solver iterations are a floor: place's contacts keep the task's own, more.
    trained = load_env_config(deployment_overrides(meta)).simulation_for("place")
    assert world.cfg.simulation_for("place").solver_iterations == trained.solver_iterations > params.solver_iterations
    assert world.cfg.simulation_for("place").physics_dt == params.physics_dt
    env = FR5Env("place", config=deployment_overrides(meta))
    try:
        labels = set()
        for seed in range(1_700_000, 1_700_008):
            world.start(seed)
            _, info = env.reset(seed=seed)
            assert world.scene().object_description == env.object_description()
            assert np.asarray(world.object_start[:2]) == pytest.approx(np.asarray(info["object_start"][:2]))
            labels.add(env.object_description().label)
        assert len(labels) >= 2, labels  # boxes as well as cylinders
    finally:
        world.close()
        env.close()


def test_a_teleported_start_is_accepted_not_latched_as_a_jump():
    """With ``episode_start: reset`` the simulator node pauses the policy node over the teleport
    and resumes it once the new state arrived; the bench must do the same, or a start far from
    where the last episode ended latches the joint-state check and the episode never begins."""
    run, env = emulation("default")
    try:
        assert run.chain.episode_start == "reset"
        far = (np.asarray(load_robot_spec().home_joint_positions) + np.array([0.0, 0.0, 0.0, 0.0, 0.0, 2.9])).tolist()
        env.start(930_010, options={"arm_positions": far})
        run.clock.now += 1.0  # a stamped state: the check compares stamps
        run._publish_joint_states(0)
        run._deliver_joint_states(1)
        assert run.reader.reading().value.positions[5] == pytest.approx(far[5], abs=1e-3)
        record = run.run_episode(930_011)
        assert record["steps"] > 0 and run.reader.reading().problem is None
    finally:
        env.close()
