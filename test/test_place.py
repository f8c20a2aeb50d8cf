"""The place task (issue #53): its goal draws, its success test, the scripted expert that solves
it, and its goal-conditioned form for HER."""
import dataclasses
import math

import numpy as np
import pytest

from fr5_rl.envs import FR5Env
from fr5_rl.expert import ScriptedExpert
from fr5_rl.goal_env import FR5PlaceGoalEnv
from fr5_rl.objects import ObjectShape
from fr5_rl.observation import GOAL_SIZE, TASK_BLOCKS
from fr5_rl.tasks import TASKS


@pytest.fixture(scope="module")
def place():
    env = FR5Env("place")
    yield env
    env.close()


def run_expert(env, seed, max_steps=400):
    expert = ScriptedExpert(env)
    env.reset(seed=seed)
    info = {}
    for _ in range(max_steps):
        _, _, terminated, truncated, info = env.step(expert.act())
        if terminated or truncated:
            break
    return info


def run_expert_measuring_the_hold(env, seed, measure):
    """One expert episode from ``seed``; returns its last info and the largest ``measure(env)``
    over the steps where both pads hold the object (0 if they never do)."""
    expert = ScriptedExpert(env)
    env.reset(seed=seed)
    largest, info = 0.0, {}
    for _ in range(env.task.max_steps):
        _, _, terminated, truncated, info = env.step(expert.act())
        if env.task_state().fingers_object_contact == 2:
            largest = max(largest, measure(env))
        if terminated or truncated:
            break
    return info, largest


def test_each_tasks_observation_blocks_are_the_observations_table():
    for name, task in TASKS.items():
        assert TASK_BLOCKS[name] == (task.include_lift, task.include_goal), name


def test_the_goal_lies_in_the_placement_region_away_from_the_object(place):
    cfg = place.cfg
    for seed in range(40):
        place.reset(seed=seed)
        draws = place.episode.draws
        goal_x, goal_y, goal_yaw = draws.goal
        assert cfg.object.region_low[0] <= goal_x <= cfg.object.region_high[0]
        assert cfg.object.region_low[1] <= goal_y <= cfg.object.region_high[1]
        assert -math.pi <= goal_yaw <= math.pi
        assert math.hypot(goal_x - draws.object_xy[0], goal_y - draws.object_xy[1]) >= cfg.place.min_goal_distance


def test_the_other_tasks_draw_no_goal():
    grasp = FR5Env("grasp")
    try:
        grasp.reset(seed=1)
        assert grasp.episode.draws.goal is None
    finally:
        grasp.close()


def test_the_scripted_expert_places_cylinders_on_seeds_it_was_not_tuned_on(place):
    results = [run_expert(place, 5000 + k) for k in range(10)]
    successes = sum(bool(info["is_success"]) for info in results)
    assert successes >= 8, [info.get("failure") for info in results]


def placed_state(place):
    """A state the place task judges a success, from a successful expert episode."""
    for seed in range(5000, 5010):
        if run_expert(place, seed)["is_success"]:
            return place.task_state()
    pytest.fail("the expert placed nothing")


def test_success_needs_every_condition_at_once(place):
    task = place.task
    state = placed_state(place)
    assert task.judge(state, place.control_dt).success
    goal_x, goal_y, _ = task.goal
    x, y, z = state.object_position
    wrong = {
        "3 cm from the goal": {"object_position": (x + 0.03, y, z), "object_start_position": state.object_start_position},
        "tilted 15 degrees": {"object_up_axis": (math.sin(math.radians(15)), 0.0, math.cos(math.radians(15)))},
        "a finger still on it": {"fingers_object_contact": 1},
        "the tcp 1 cm above its top": {"tcp_position": (state.tcp_position[0], state.tcp_position[1],
                                                        z + task.shape.size[2] / 2 + 0.01)},
    }
    for why, change in wrong.items():
        task._previous_object = state.object_position  # at rest
        assert not task.judge(dataclasses.replace(state, **change), place.control_dt).success, why
    task._previous_object = (x, y, z + 0.01)  # moving 0.5 m/s
    assert not task.judge(state, place.control_dt).success, "still moving"


def test_a_boxs_yaw_counts_modulo_its_symmetry(place):
    task = place.task
    state = placed_state(place)
    goal_x, goal_y, _ = task.goal
    square, rectangle = ObjectShape("box", (0.05, 0.05, 0.05)), ObjectShape("box", (0.06, 0.03, 0.05))
    for shape, offset, success in ((square, 92.0, True), (square, 45.0, False), (rectangle, 92.0, False),
                                   (rectangle, 185.0, True), (rectangle, 12.0, False)):
        task.shape = shape
        task.goal = (goal_x, goal_y, 0.0)
        yaw = math.radians(offset)
        quaternion = (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
        task._previous_object = state.object_position
        clear = (state.tcp_position[0], state.tcp_position[1], state.object_position[2] + 0.2)
        judged = task.judge(dataclasses.replace(state, object_quaternion=quaternion, tcp_position=clear),
                            place.control_dt)
        assert judged.success == success, (shape.symmetry_order, offset)


def test_the_goal_env_gives_the_place_observation_and_a_goal_only_reward():
    env = FR5PlaceGoalEnv(config={"object": {"variety": {"enabled": True}}})
    try:
        observation, _ = env.reset(seed=11)
        flat, _ = env.env.reset(seed=11)
        np.testing.assert_array_equal(observation["observation"], flat[:-GOAL_SIZE])
        achieved, desired = observation["achieved_goal"], observation["desired_goal"]
        assert env.compute_reward(achieved, desired, {}) == -1.0  # the goal is >= 10 cm away
        assert env.compute_reward(desired, desired, {}) == 0.0
        batch = np.stack([desired, achieved, desired])
        np.testing.assert_array_equal(env.compute_reward(batch, np.stack([desired] * 3), [{}] * 3), [0.0, -1.0, 0.0])
        # A square box 78 degrees off its goal yaw is 12 off by its symmetry: too far; 96 is 6 off.
        square_goal = np.array([0.0, 0.0, 0.0, 1.0, 1.0], dtype=np.float32)
        for degrees, reward in ((78.0, -1.0), (96.0, 0.0), (0.0, 0.0)):
            angle = 4 * math.radians(degrees)
            achieved_yaw = np.array([0.0, 0.0, math.sin(angle), math.cos(angle), 1.0], dtype=np.float32)
            assert env.compute_reward(achieved_yaw, square_goal, {}) == reward, degrees
        cylinder_goal = np.array([0.0, 0.0, 0.0, 0.0, 0.0], dtype=np.float32)
        assert env.compute_reward(np.array([0.01, 0.0, 0.0, 0.0, 0.0], dtype=np.float32), cylinder_goal, {}) == 0.0
    finally:
        env.close()


@pytest.mark.parametrize("task, at_least", [("grasp", 9), ("place", 7)])
def test_the_expert_grasps_boxes_at_any_yaw_and_places_them_at_the_goals_yaw(task, at_least):
    """Boxes at random yaws: the expert turns the gripper to close across the narrower side and,
    placing, turns the box to the goal's yaw by its symmetry (without the turn: place fails).
    Held-out seeds; 10/10 and 8/10 measured."""
    env = FR5Env(task, config={"object": {"variety": {"enabled": True, "kinds": ["box"]}}})
    try:
        results = [run_expert(env, seed, env.task.max_steps) for seed in range(7000, 7010)]
        assert sum(bool(info["is_success"]) for info in results) >= at_least, [i.get("failure") for i in results]
    finally:
        env.close()


def test_the_scripted_expert_places_the_drawn_boxes_and_cylinders():
    """Boxes at any yaw and cylinders of every drawn size and mass (object.variety), on seeds the
    expert was never tuned on: the demonstrations DAgger learns the place model from."""
    env = FR5Env("place", config={"object": {"variety": {"enabled": True}}, "observation": {"object_features": True}})
    try:
        results = [(run_expert(env, 9100 + k), env.episode.plant.object_shape.kind) for k in range(12)]
    finally:
        env.close()
    assert {kind for _, kind in results} == {"box", "cylinder"}
    successes = sum(bool(info["is_success"]) for info, _ in results)
    assert successes >= 11, [(kind, info.get("failure")) for info, kind in results]


def test_the_scripted_expert_places_under_the_robustness_perturbations():
    """Noise, a step of latency, mass and friction +-20 % (docs/robustness/fr5/place_all_together.json),
    held-out seeds. Before stop 62 the expert closed 15 mm above a short box's centre and held it by
    its top edge, and at 20 solver iterations the pads sank into a cylinder and pushed it out of
    the hand: 26/30 here (88 % over 100 seeds); since, 28/30 (98.5 % over 200)."""
    import json

    from fr5_rl.config import package_root

    overrides = json.loads((package_root() / "docs" / "robustness" / "fr5" / "place_all_together.json").read_text())
    env = FR5Env("place", config=overrides["env_overrides"])
    try:
        results = [run_expert(env, 9200 + k) for k in range(30)]
    finally:
        env.close()
    assert sum(bool(info["is_success"]) for info in results) >= 28, [info.get("failure") for info in results]


def test_the_scripted_expert_places_with_actions_in_tcp_space():
    """``action.space: tcp``: the expert's step as a tcp step, which the shaper's inverse
    kinematics turns back into joint increments. The same task solved as often as in joint space
    (100 perturbed seeds, 1,700,000+: 95 against 96), so its labels can teach a tcp-space learner;
    held-out seeds here. A wrong axis, sign or scale in either conversion drops it near zero."""
    env = FR5Env("place", config={"object": {"variety": {"enabled": True}}, "observation": {"object_features": True},
                                  "action": {"space": "tcp"}})
    try:
        results = [run_expert(env, 9300 + k) for k in range(12)]
    finally:
        env.close()
    assert sum(bool(info["is_success"]) for info in results) >= 11, [info.get("failure") for info in results]


def test_the_expert_closes_low_on_a_short_box():
    """A short box is held by at least ``min_top_above_tcp`` of its side (with the pads' tips
    ``tip_clearance`` clear of the table), not by its top edge; a tall object with its top short
    of the palm, as before."""
    env = FR5Env("place", config={"object": {"variety": {"enabled": True, "kinds": ["box"]}}})
    try:
        expert = ScriptedExpert(env)
        heights = []
        for seed in range(40):
            env.reset(seed=seed)
            height = env.episode.plant.object_shape.size[2]
            heights.append(height)
            offset = expert._grasp_offset()
            tips_above_table = height / 2.0 + offset - expert.pad_tips_below_tcp
            top_above_tcp = height / 2.0 - offset
            assert tips_above_table >= expert.tip_clearance - 1e-9
            assert top_above_tcp <= expert.finger_reach + 1e-9
            assert top_above_tcp >= min(expert.min_top_above_tcp, height - expert.pad_tips_below_tcp
                                        - expert.tip_clearance) - 1e-9
        assert min(heights) < 0.04 < 0.08 < max(heights)
    finally:
        env.close()


@pytest.mark.parametrize("task, expected", [("place", 0.02), ("grasp", 0.001)])
def test_the_objects_torsional_friction_is_the_tasks(task, expected):
    """The place task's carried objects turn in the grasp unless the pads' contact patch resists
    (env.yaml place.simulation); grasp keeps what its shipped model was trained with. The
    simulator node (at its own physics step) builds the same world as gym: the rehearsal's figures
    are this world's."""
    import pybullet

    from fr5_rl.episode_runner import simulator_episode
    from fr5_rl.sim.node_params import load_sim_node_params

    env = FR5Env(task)
    node_episode = simulator_episode(task, None, {}, load_sim_node_params("fairino"))
    try:
        env.reset(seed=0)
        node_episode.start(0)
        for world in (env.episode.plant.world, node_episode.plant.world):
            spinning = pybullet.getDynamicsInfo(world.object_id, -1, physicsClientId=world.client)[7]
            assert spinning == pytest.approx(expected)
    finally:
        env.close()
        node_episode.close()


class TestTheExpertsLabelsWhereLearnersStalled:
    """States a learner reached and stalled in (the place model of stop 58 hovered or froze
    there), built from a reset state; the expert's label must point one way out."""

    @pytest.fixture()
    def tall_cylinder(self):
        env = FR5Env("place", config={"object": {"variety": {"enabled": True, "kinds": ["cylinder"]}}})
        for seed in range(200):
            env.reset(seed=seed)
            if env.episode.plant.object_shape.size[2] > 0.10:
                yield env
                env.close()
                return
        pytest.fail("no cylinder taller than 10 cm drawn")

    @staticmethod
    def label(env, monkeypatch, command_width=None, **state_changes):
        state = dataclasses.replace(env.task_state(), **state_changes)
        monkeypatch.setattr(env, "task_state", lambda: state)
        if command_width is not None:
            monkeypatch.setattr(env.episode.chain, "gripper_command_width", command_width)
        expert = ScriptedExpert(env)
        action = expert.act()
        return expert.phase, action

    def test_over_a_tall_object_it_aligns_before_its_fingers_reach_the_top(self, tall_cylinder, monkeypatch):
        env = tall_cylinder
        x, y, z = env.task_state().object_position
        top = z + env.episode.plant.object_shape.size[2] / 2.0
        # The pads' tips are about 1 cm below the tcp: 2 cm above the top, 1.8 cm to the side.
        phase, _ = self.label(env, monkeypatch, tcp_position=(x + 0.018, y, top + 0.02))
        assert phase == "hover"
        phase, _ = self.label(env, monkeypatch, tcp_position=(x + 0.004, y, top + 0.02))
        assert phase == "descend"

    def test_a_lifted_object_in_both_pads_is_held_whatever_the_command(self, place, monkeypatch):
        place.reset(seed=3)
        state = place.task_state()
        lifted = (state.object_position[0], state.object_position[1], state.object_position[2] + 0.03)
        half_open = 0.6 * place.robot_spec.max_opening_width
        phase, action = self.label(place, monkeypatch, command_width=half_open, object_position=lifted,
                                   fingers_object_contact=2,
                                   tcp_position=(lifted[0], lifted[1], lifted[2] + 0.02))
        assert phase in ("carry", "lower") and action[6] == -1.0

    def test_letting_go_once_begun_goes_on_over_a_wider_band(self, place, monkeypatch):
        place.reset(seed=3)
        state = place.task_state()
        goal_x, goal_y, _ = place.task.goal
        rest_z = state.object_start_position[2]
        # 15 mm from the goal (beyond the 12 mm where a closed hand lets go), 4 mm above the table.
        carried = (goal_x + 0.015, goal_y, rest_z + 0.004)
        common = dict(object_position=carried, fingers_object_contact=2,
                      tcp_position=(carried[0], carried[1], carried[2] + 0.02))
        width = place.robot_spec.max_opening_width
        phase, action = self.label(place, monkeypatch, command_width=0.0, **common)
        assert phase == "lower" and action[6] == -1.0
        phase, action = self.label(place, monkeypatch, command_width=0.4 * width, **common)
        assert phase == "release" and action[6] == 1.0

    def test_at_the_funnels_edge_the_label_closes_in_sideways_not_up_and_over(self, place, monkeypatch):
        """Just outside the descent funnel the old label went 10 cm up, just inside straight down;
        a learner averaged them and sank beside the object. Along the cone it moves in."""
        place.reset(seed=3)
        state = place.task_state()
        expert = ScriptedExpert(place)
        x, y, z = state.object_position
        grasp_z = z + expert._grasp_offset()
        apex = grasp_z + expert._top_above_grasp(expert._grasp_offset())
        height = apex + 0.02
        error = expert.align_tolerance + expert.funnel_slope * 0.02 + 0.002
        start = (x + error, y, height)
        # Joints that put the tcp there, pointing down.
        q = expert._inverse_kinematics(start, state.joint_positions)
        _, action = self.label(place, monkeypatch, tcp_position=start, joint_positions=q)
        moved = place.kinematics.tcp_pose(np.asarray(q) + action[:6] * place.cfg.action.max_joint_step)[0] \
            - place.kinematics.tcp_pose(q)[0]
        assert moved[0] < -0.002  # toward the object
        assert abs(moved[2]) < 0.5 * abs(moved[0]), moved

    def test_letting_go_the_hand_rises_only_once_the_fingers_clear_the_object(self, monkeypatch):
        """Stop 64: at 90 % of the stroke (72 mm) the hand rose 2 mm over the grip of a 70 mm
        object, and a learner, unable to tell the two widths apart, rose while it held it. The
        hand now waits for the object's width across the fingers and a margin."""
        env = FR5Env("place", config={"object": {"variety": {"enabled": True, "kinds": ["cylinder"]}}})
        try:
            wide = next(seed for seed in range(300)
                        if env.reset(seed=seed) is not None and env.episode.plant.object_shape.size[1] > 0.066)
            env.reset(seed=wide)
            state = env.task_state()
            goal_x, goal_y, _ = env.task.goal
            standing = (goal_x, goal_y, state.object_start_position[2])  # set down on the goal
            diameter = env.episode.plant.object_shape.size[1]
            common = dict(object_position=standing, fingers_object_contact=0,
                          tcp_position=(goal_x, goal_y, standing[2] + 0.01))
            width = env.robot_spec.max_opening_width
            for opening, expected in ((0.9 * width, "release"), (diameter + 0.004, "release"),
                                      (min(diameter + 0.009, 0.96 * width), "retreat")):
                phase, action = self.label(env, monkeypatch, command_width=width, gripper_width=opening, **common)
                assert phase == expected, (opening, diameter)
                assert action[6] == 1.0
        finally:
            env.close()

    def test_over_a_cylinder_the_hand_keeps_whatever_yaw_it_has(self, monkeypatch):
        """A cylinder's yaw does not matter: the label never turns the hand (before stop 64 it
        turned it back to home's yaw, which a learner could only read off the joints)."""
        env = FR5Env("place", config={"object": {"variety": {"enabled": True, "kinds": ["cylinder"]}},
                                      "action": {"space": "tcp"}})
        try:
            env.reset(seed=5)
            turned = np.array(env.task_state().joint_positions)
            turned[5] += 0.5  # the wrist turned half a radian away from home's yaw
            x, y, z = env.task_state().object_position
            for tcp, contacts in (((x + 0.05, y, z + 0.1), 0), ((x, y, z + 0.03), 0), ((x, y, z + 0.015), 2)):
                _, action = self.label(env, monkeypatch, joint_positions=tuple(turned), tcp_position=tcp,
                                       fingers_object_contact=contacts)
                assert action[5] == pytest.approx(0.0, abs=1e-6)
        finally:
            env.close()

    def test_over_a_square_top_the_hand_keeps_the_aligned_yaw_it_has(self, monkeypatch):
        """A square top looks the same every quarter turn, and so does the observation's
        (sin 4Δ, cos 4Δ); a hand aligned a quarter turn from home's choice is told not to turn."""
        from fr5_rl.objects import yaw_of

        env = FR5Env("grasp", config={"object": {"variety": {"enabled": True, "kinds": ["box"]}}})
        try:
            for seed in range(100):
                env.reset(seed=seed)
                if env.episode.plant.object_shape.symmetry_order == 4:
                    break
            else:
                pytest.fail("no square top drawn")
            state = env.task_state()
            object_yaw = yaw_of(state.object_quaternion)

            def tcp_yaw(q):
                rotation = env.kinematics.tcp_pose(q)[1]
                return math.atan2(rotation[1, 0], rotation[0, 0])

            q = np.asarray(state.joint_positions, dtype=float)
            # Turn the wrist so that the hand lines up with the top a quarter turn away from
            # where the home-nearest choice would put it.
            home_choice = object_yaw + (math.pi / 2) * round((tcp_yaw(q) - object_yaw) / (math.pi / 2))
            def wrapped(angle):
                return (angle + math.pi) % (2 * math.pi) - math.pi

            target = home_choice + math.pi / 2
            turned = q.copy()
            for _ in range(5):  # the wrist turns the tcp's yaw the other way, nearly one for one
                turned[5] -= wrapped(target - tcp_yaw(turned))
            assert abs(wrapped(tcp_yaw(turned) - target)) < 1e-3
            x, y, z = state.object_position
            tcp = env.kinematics.tcp_pose(turned)[0]
            _, action = self.label(env, monkeypatch, joint_positions=tuple(turned), tcp_position=tuple(tcp))
            stepped = np.asarray(turned) + action[:6] * env.cfg.action.max_joint_step
            turn = (tcp_yaw(stepped) - tcp_yaw(turned) + math.pi) % (2 * math.pi) - math.pi
            assert abs(math.degrees(turn)) < 0.3, math.degrees(turn)
        finally:
            env.close()

    def test_a_hand_still_turning_holds_above_a_box_until_aligned(self, monkeypatch):
        """The hand came down while it turned and closed across a box's corners, 36 degrees off
        its faces. Straight above the box, a hand 30 degrees off its faces is told to stay up
        (and turn); the same hand aligned is told to go down."""
        env = FR5Env("grasp", config={"object": {"variety": {"enabled": True, "kinds": ["box"]}}})
        try:
            env.reset(seed=5)
            state = env.task_state()
            expert = ScriptedExpert(env)
            x, y, z = state.object_position
            grasp_z = z + expert._grasp_offset()
            above_apex = (x, y, grasp_z + expert._top_above_grasp(expert._grasp_offset()) + 0.01)

            def wrist_turned_by(offset):
                q = np.asarray(expert._inverse_kinematics(above_apex, state.joint_positions), dtype=float)
                turned = dataclasses.replace(state, joint_positions=tuple(q))
                wanted = expert._yaw_error(turned) + offset
                for _ in range(5):  # the wrist turns the tcp's yaw the other way, nearly one for one
                    q[5] -= wanted
                    wanted = expert._yaw_error(dataclasses.replace(state, joint_positions=tuple(q))) + offset
                return q

            for offset, phase_wanted in ((math.radians(30.0), "hover"), (0.0, "descend")):
                q = wrist_turned_by(offset)
                tcp = env.kinematics.tcp_pose(q)[0]
                assert np.allclose(tcp, above_apex, atol=1e-3)
                phase, action = self.label(env, monkeypatch, joint_positions=tuple(q), tcp_position=tuple(tcp))
                assert phase == phase_wanted, (math.degrees(offset), phase)
                stepped = env.kinematics.tcp_pose(q + action[:6] * env.cfg.action.max_joint_step)[0]
                if phase_wanted == "hover":
                    assert stepped[2] - tcp[2] > -0.0005  # not down
                else:
                    assert stepped[2] - tcp[2] < -0.001
        finally:
            env.close()


def test_the_expert_sets_a_held_object_down_where_the_policy_sees_it():
    """With the tracker's hold modelled (``target_in_hand_from_grasp``) the policy sees a held
    object fixed in the tcp frame from the grasp, not where a slip in the grip took it; the
    expert's labels place that object, or a learner is told to move one it sees on the goal."""
    camera = {"object": {"variety": {"enabled": True}}, "observation": {"object_features": True},
              "randomisation": {"enabled": True, "plain_episode_share": 0.0, "target_share": 1.0,
                                "target_hidden_radius": 0.15, "target_in_hand_from_grasp": True}}
    env = FR5Env("place", config=camera)
    try:
        expert = ScriptedExpert(env)
        env.reset(seed=9300)
        target = env.episode.chain.target
        assert target is not None and target.held_in_tcp is None and expert._held_as_the_policy_sees() is None
        for _ in range(300):
            env.step(expert.act())
            if target.held_in_tcp is not None and expert.phase == "lower":  # over the goal
                break
        assert target.held_in_tcp is not None and expert.phase == "lower", "the expert never carried it to the goal"
        position, rotation = env.episode.tcp_pose()
        assert expert._held_as_the_policy_sees() == pytest.approx(tuple(position + rotation @ target.held_in_tcp))
        label = expert.act()
        target._in_tcp = target.held_in_tcp + rotation.T @ np.array([0.03, 0.0, 0.0])  # seen 3 cm further along x
        assert not np.allclose(expert.act(), label, atol=1e-3)
    finally:
        env.close()
    plain = FR5Env("place")
    try:
        plain.reset(seed=9300)
        assert ScriptedExpert(plain)._held_as_the_policy_sees() is None
    finally:
        plain.close()


@pytest.mark.parametrize("coupled", [True, False])
def test_coupled_fingers_keep_a_carried_object_centred(coupled):
    """The gripper's linkage moves both fingers mirrored (``simulation.fingers_coupled``, the place
    task's physics), so the object the expert carries to the goal stays centred between them, as
    the detector's tracker assumes. Uncoupled, the two fingers, each squeezing at its force limit,
    drift with the object along the closing axis: 7 mm (median) to 20 mm over 60 carries."""
    env = FR5Env("place", config={"object": {"variety": {"enabled": True}}, "observation": {"object_features": True},
                                  "place": {"simulation": {"fingers_coupled": coupled}}})
    def drift(env):
        left, right = env.episode.plant.robot.joint_lists_with_fingers()[0][6:8]
        return abs(left - right) / 2.0

    try:
        largest = [run_expert_measuring_the_hold(env, seed, drift)[1] for seed in range(9400, 9406)]
    finally:
        env.close()
    if coupled:
        assert max(largest) < 0.001, largest
    else:
        assert max(largest) > 0.004, largest


def test_the_expert_carries_without_shaking_the_object_out_of_a_small_arms_hand():
    """The FR3 (110 N m shoulder) in the world its place model learns in: carried at the FR5's 8 mm
    a step from a standstill, its objects turned out of the pads: 76 of 100 placed, most of the
    rest knocked over; lifted gently and carried at a pace scaled by its arm span, 97-99 of 100
    (seeds 7,000,000+ and 7,100,000+). Held-out seeds here: 20 of 20, and 17 before the change."""
    from fr5_rl.training.hyperparameters import read_hyperparameter_file

    env = FR5Env("place", config={**read_hyperparameter_file("dagger_place_tcp")["env"], "robot": "fr3"})
    try:
        results = [run_expert(env, 7_300_000 + k, env.task.max_steps) for k in range(20)]
    finally:
        env.close()
    assert sum(bool(info["is_success"]) for info in results) >= 18, [info.get("failure") for info in results]


def test_the_expert_holds_a_box_up_until_a_slow_turn_is_done():
    """A learner a few steps behind on the turn to the goal's yaw was told to lower and let go over
    the goal, and set boxes down 12 and 32 degrees off. The expert now counts the turn still to
    make as distance to the goal. Here its own turn is halved while it carries (a lagging learner):
    25 of 30 placed before the change (four timed out and one fell, the boxes 15-33 degrees off),
    30 of 30 after."""
    from fr5_rl.training.hyperparameters import read_hyperparameter_file

    env = FR5Env("place", config=read_hyperparameter_file("dagger_place_tcp")["env"])
    outcomes = []
    try:
        for seed in range(7_500_000, 7_500_030):
            expert = ScriptedExpert(env)
            env.reset(seed=seed)
            for _ in range(env.task.max_steps):
                action = expert.act()
                if expert.phase in ("carry", "lower"):
                    action[5] *= 0.5  # the turn about the vertical (action.space: tcp)
                _, _, terminated, truncated, info = env.step(action)
                if terminated or truncated:
                    break
            yaw_error = math.degrees(env.task.yaw_error(env.task_state()))
            outcomes.append((bool(info["is_success"]), info.get("failure"), round(yaw_error, 1)))
    finally:
        env.close()
    assert sum(success for success, _, _ in outcomes) >= 28, [outcome for outcome in outcomes if not outcome[0]]


def test_a_carried_object_stays_upright_between_the_pads():
    """PyBullet meets a cylinder with one point per pad, at different heights on the two pads, and
    only the torsional friction holds the object from turning about the line between them. At 10
    mm of it (``place.simulation.object_spinning_friction`` 0.01) carried objects turned up to 17
    degrees in the FR16's pads at a constant speed (3 of these 40; 1 of 40 on the FR10, 26 degrees)
    and the FR16's expert placed 281 of 300 under the perturbations; at 20 mm, for the rubber patch
    one simulated point lacks (docs/experiments.md, stop 69), none turned more than 8 degrees and it
    placed 296."""
    from fr5_rl.training.hyperparameters import read_hyperparameter_file

    env = FR5Env("place", config={**read_hyperparameter_file("dagger_place_tcp")["env"], "robot": "fr16"})
    def tilt(env):
        return math.degrees(math.acos(min(1.0, float(env.task_state().object_up_axis[2]))))

    outcomes = []
    try:
        for seed in range(7_400_000, 7_400_040):
            info, worst_tilt = run_expert_measuring_the_hold(env, seed, tilt)
            outcomes.append((seed, bool(info["is_success"]), round(worst_tilt, 1)))
    finally:
        env.close()
    assert all(tilt <= 10.0 for _, _, tilt in outcomes), [outcome for outcome in outcomes if outcome[2] > 10.0]
    assert sum(success for _, success, _ in outcomes) >= 38, [outcome for outcome in outcomes if not outcome[1]]
