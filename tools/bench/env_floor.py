"""The floor an environment step is measured against (tools/bench/env_and_inference.py): the same
episodes' motor commands replayed in a bare world (robot, table, object: no Python env around
them), with the four state queries an env needs, and on the URDF alone; and the resting scene's
cost per physics step. The env bench divides the environment's speed by these."""
from __future__ import annotations

import math
import time
from typing import Any, Dict, List

import numpy as np


def run_seeded_episodes(env, actions: np.ndarray, first_seed: int) -> List[int]:
    """Step ``env`` through ``actions``, resetting with seeds first_seed, first_seed + 1, ...
    whenever an episode ends; returns the seeds used. Every start is reproducible, which is
    what lets the bare replay rebuild it."""
    seeds = [first_seed]
    step, reset = env.step, env.reset
    reset(seed=first_seed)
    for action in actions:
        _, _, terminated, truncated, _ = step(action)
        if terminated or truncated:
            seeds.append(seeds[-1] + 1)
            reset(seed=seeds[-1])
    return seeds


def record_episodes(env, actions: np.ndarray, first_seed: int) -> List[Dict[str, Any]]:
    """The same run as :func:`run_seeded_episodes`, untimed, recording every motor command the
    env sends (the eight position targets PyBullet gets, fingers included) with the number of
    physics steps it stands for, the joint state each episode starts from, the joint angles it
    ends with, whether the robot touched anything (a contact at the end of any control step),
    the actions, and the index of the command each control period ended with.
    Randomised episodes (a command late within the period, a physics step drawn per episode) are
    recorded as they run: one entry per motor call."""
    import pybullet as p

    plant = env.plant
    robot, world = plant.robot, plant.world
    original_command, original_step, original_step_physics = plant.command, plant.step_period, plant.step_physics
    episodes: List[Dict[str, Any]] = []

    def command(joint_targets, opening_width, period=None):
        original_command(joint_targets, opening_width, period)
        finger = robot._finger_target
        episodes[-1]["commands"].append([[float(v) for v in joint_targets] + [finger, finger], 0])

    def step():
        original_step()
        episodes[-1]["commands"][-1][1] += world.substeps

    def step_physics():
        original_step_physics()
        episodes[-1]["commands"][-1][1] += 1

    original_reset, original_env_step = env.reset, env.step

    def reset(seed=None, options=None):
        if episodes:
            episodes[-1]["final_joint_positions"] = env.joint_positions()
        episodes.append({"seed": seed, "commands": [], "steps": 0, "touched": False, "period_ends": [], "actions": []})
        result = original_reset(seed=seed, options=options)
        episodes[-1].update(commands=[], physics_dt=world.physics_dt,  # reset's own hold command: replayed by the reset
                            start=robot.joint_lists_with_fingers()[0], object_start=env.episode.object_pose()[:2])
        return result

    def env_step(action):
        episodes[-1]["steps"] += 1
        result = original_env_step(action)
        episodes[-1]["period_ends"].append(len(episodes[-1]["commands"]) - 1)
        episodes[-1]["actions"].append(action)
        if not episodes[-1]["touched"]:
            episodes[-1]["touched"] = bool(p.getContactPoints(bodyA=robot.body, physicsClientId=world.client))
        return result

    plant.command, plant.step_period, plant.step_physics, env.reset, env.step = command, step, step_physics, reset, env_step
    try:
        run_seeded_episodes(env, actions, first_seed)
        episodes[-1]["final_joint_positions"] = env.joint_positions()
    finally:
        plant.command, plant.step_period, plant.step_physics = original_command, original_step, original_step_physics
        del env.reset, env.step  # back to the class methods
    return episodes


def replay_bare(env, episodes: List[Dict[str, Any]], with_queries: bool = False,
                minimal_env: bool = False) -> Dict[str, float]:
    """Bare PyBullet doing the env's physics in the env's own world (robot, table, object): per
    control step the recorded ``setJointMotorControlArray`` call(s) and their ``stepSimulation``
    calls, nothing else. Each episode's start is rebuilt with the env's own seeded reset (not
    timed); the timed part then starts with a bare reset to that start (one
    ``resetJointStatesMultiDof`` and one ``resetBasePositionAndOrientation``), so the reference
    resets as often as the env does. Returns the timed seconds and how far the replayed joints
    ended from the env's (rad), which shows the replay is the same motion.

    ``with_queries`` adds, at the end of every control period, the four state queries any
    environment of this task needs (joint states, tcp link state, object pose, the robot's
    contacts) and does nothing with their results: the floor a Python environment on PyBullet
    can reach.

    ``minimal_env`` ends every control period with the least any gymnasium environment of
    these tasks does in Python: the action to clipped floats, the four queries, an
    observation array (joint angles and velocities, tcp and object positions), a distance reward
    with an action penalty, a success test and an ``info`` dict.
    ``env_reset_seconds`` is the time of the env's own resets (run untimed before each episode to
    rebuild its start): added to a minimal env's time, it gives one that resets as this env does."""
    import pybullet as p

    client = env.plant.world.client
    robot = env.plant.robot
    body, joints, tcp = robot.body, robot.all_joints, robot.tcp_link
    motor, step_simulation, perf = p.setJointMotorControlArray, p.stepSimulation, time.perf_counter
    reset_joints, reset_base = p.resetJointStatesMultiDof, p.resetBasePositionAndOrientation
    change_dynamics = p.changeDynamics
    gains = dict(forces=robot._forces, positionGains=robot._position_gains, velocityGains=robot._velocity_gains,
                 physicsClientId=client)
    get_joints, get_link, get_pose, get_contacts = (
        p.getJointStates, p.getLinkState, p.getBasePositionAndOrientation, p.getContactPoints)
    seconds, deviation, env_reset_seconds = 0.0, 0.0, 0.0
    for episode in episodes:
        t0 = perf()
        env.reset(seed=episode["seed"])
        env_reset_seconds += perf() - t0
        commands, start, zeros = episode["commands"], [[v] for v in episode["start"]], [[0.0]] * len(joints)
        obj, (position, orientation) = env.plant.world.object_id, episode["object_start"]
        period_ends, actions = iter(episode["period_ends"]), iter(episode["actions"])
        period_end = next(period_ends, -1)
        t0 = perf()
        reset_joints(body, joints, start, targetVelocities=zeros, physicsClientId=client)
        reset_base(obj, position, orientation, physicsClientId=client)
        settling = True  # the object sleeps from the end of its first physics step, as in the env
        for index, (targets, physics_steps) in enumerate(commands):
            motor(body, joints, p.POSITION_CONTROL, targetPositions=targets, **gains)
            for _ in range(physics_steps):
                step_simulation(physicsClientId=client)
                if settling:
                    change_dynamics(obj, -1, activationState=p.ACTIVATION_STATE_SLEEP, physicsClientId=client)
                    settling = False
            if index != period_end:  # a command within the period (randomised timing)
                continue
            period_end = next(period_ends, -1)
            if with_queries or minimal_env:
                results = (get_joints(body, joints, physicsClientId=client),
                           get_link(body, tcp, computeForwardKinematics=1, physicsClientId=client),
                           get_pose(obj, physicsClientId=client), get_contacts(bodyA=body, physicsClientId=client))
                if minimal_env:
                    _minimal_env_step(next(actions), *results)
        seconds += perf() - t0
        deviation = max(deviation, float(np.max(np.abs(env.joint_positions() - episode["final_joint_positions"]))))
    return {"seconds": seconds, "max_final_joint_deviation_rad": deviation, "env_reset_seconds": env_reset_seconds}


def _minimal_env_step(action: np.ndarray, joint_states: tuple, tcp_link: tuple, object_pose: tuple,
                      contacts: tuple) -> tuple:
    """The least a gymnasium environment of these tasks computes per step, in Python, from the
    four queries' results (:func:`replay_bare`'s ``minimal_env``): the step's return value."""
    values = [1.0 if value > 1.0 else (-1.0 if value < -1.0 else value) for value in action.tolist()]
    tcp_position, object_position = tcp_link[4], object_pose[0]
    distance = math.dist(tcp_position, object_position)
    observation = np.array([state[0] for state in joint_states] + [state[1] for state in joint_states]
                           + list(tcp_position) + list(object_position), dtype=np.float32)
    reward = -distance - 0.001 * sum(value * value for value in values)
    success = distance < 0.02
    return observation, reward, success, False, {"is_success": success, "failure": "collision" if contacts else None}


def replay_urdf_only(env, episodes: List[Dict[str, Any]]) -> Dict[str, float]:
    """Bare PyBullet stepping the same URDF alone (no table, no object) through the same
    commands: its own client with the env's gravity, physics step (per episode, as drawn),
    solver iterations, joint speed cap (the robot's own function: PyBullet keeps one per body)
    and joint damping; per episode a timed ``resetJointStatesMultiDof`` to the env's start, then
    per control step the recorded position targets and ``stepSimulation`` calls. The arm moves as
    in the env until it touches something there. Returns the timed seconds and, of the episodes
    in which the env's robot touched nothing, the share that ended where the env's did (every
    joint within 1e-6 rad): the check that the reference is the same motion (1.0 when it is)."""
    import pybullet as p

    from fr5_rl.sim.robot import cap_joint_speeds, urdf_for_pybullet

    robot, sim = env.plant.robot, env.cfg.simulation_for(env.task.name)
    client = p.connect(p.DIRECT)
    try:
        p.setGravity(0.0, 0.0, sim.gravity, physicsClientId=client)
        p.setPhysicsEngineParameter(numSolverIterations=sim.solver_iterations, deterministicOverlappingPairs=1,
                                    physicsClientId=client)
        body = p.loadURDF(urdf_for_pybullet(robot.spec.model), basePosition=[0, 0, 0], useFixedBase=True,
                          flags=p.URDF_USE_INERTIA_FROM_FILE, physicsClientId=client)
        joints = robot.all_joints
        cap_joint_speeds(body, robot.spec, client)
        gains = dict(forces=robot._forces, positionGains=robot._position_gains,
                     velocityGains=robot._velocity_gains, physicsClientId=client)
        motor, step_simulation, perf = p.setJointMotorControlArray, p.stepSimulation, time.perf_counter
        zeros, seconds, untouched, same_motion = [[0.0]] * len(joints), 0.0, 0, 0
        for episode in episodes:
            env.reset(seed=episode["seed"])  # the episode's damping, as the env drew it
            p.setTimeStep(episode["physics_dt"], physicsClientId=client)
            for index in robot.arm_joints:
                p.changeDynamics(body, index, jointDamping=float(robot._joint_damping or 0.0), physicsClientId=client)
            start = [[v] for v in episode["start"]]
            t0 = perf()
            p.resetJointStatesMultiDof(body, joints, start, targetVelocities=zeros, physicsClientId=client)
            for targets, physics_steps in episode["commands"]:
                motor(body, joints, p.POSITION_CONTROL, targetPositions=targets, **gains)
                for _ in range(physics_steps):
                    step_simulation(physicsClientId=client)
            seconds += perf() - t0
            if not episode["touched"]:
                final = [state[0] for state in p.getJointStates(body, robot.arm_joints, physicsClientId=client)]
                untouched += 1
                same_motion += bool(np.max(np.abs(np.subtract(final, episode["final_joint_positions"]))) < 1e-6)
    finally:
        p.disconnect(physicsClientId=client)
    return {"seconds": seconds, "same_motion_share": same_motion / untouched if untouched else float("nan")}


def resting_step_seconds(env, steps: int, seed: int) -> float:
    """``stepSimulation`` of the scene right after a reset with nothing moving (the arm holds
    its start, the object rests): shown for comparison."""
    import pybullet as p

    client = env.plant.world.client
    env.reset(seed=seed)
    state = p.saveState(physicsClientId=client)
    step_simulation, perf = p.stepSimulation, time.perf_counter
    t0 = perf()
    for _ in range(steps * env.plant.world.substeps):
        step_simulation(physicsClientId=client)
    seconds = perf() - t0
    p.restoreState(stateId=state, physicsClientId=client)
    p.removeState(state, physicsClientId=client)
    return seconds


# The shipped randomisation each task trains under: these files' env overrides.
