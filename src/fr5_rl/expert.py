"""A scripted expert for both tasks: inverse-kinematics waypoints turned into actions.

It reads the simulator's ground truth (object pose, joint state) and emits the same 7-D
actions a policy would, so it exercises the full action path. Used as a baseline, by the
tests (a task that the expert cannot solve is a broken task), and for demonstrations.
"""
from __future__ import annotations

import math
from typing import List, Optional, Sequence, Tuple

import numpy as np

from .config import DEFAULT_ROBOT, load_robot_spec
from .control import yaw_of_rotation
from .envs import FR5Env
from .kinematics import InverseKinematics
from .objects import yaw_of


class ScriptedExpert:
    """Waypoint expert: above the object -> down to it -> (grasp) close -> lift and hold.

    It keeps no memory between calls: the phase is read off the current state each step
    (where the tcp is relative to the object, whether both finger pads touch it), so it can
    label any state a learner visits (DAgger) and recovers when something goes wrong.
    """

    hover_height = 0.10  # m above the object centre before descending
    lift_clearance = 0.10  # m the expert lifts (the task needs lift_height)
    grasp_height_offset = 0.015  # m above the object centre where the fingers close
    # ... but no lower than this below a tall object's top: the pads reach this far down before
    # the palm touches the top.
    finger_reach = 0.025  # 1.5 cm short of where the palm meets the top: at 1 cm a learner a step late hit it
    max_turn_step = 0.03  # rad the hand's yaw is asked to turn per step (the wrist may do 0.04)
    pad_tips_below_tcp = 0.01  # m (urdf: the pads reach 1 cm beyond the tcp)
    # A grip 15 mm above the centre held a 36 mm box by its top 13 mm, and it turned out of the
    # pads as it rose: on a short object the pads close with its top this far above the tcp (20
    # mm of pad on it), their tips no nearer the table than tip_clearance. Lower still (every
    # object as low as the table allows) learners pressing it down at the goal pushed the top of
    # a 5 cm object into the palm (docs/experiments.md, stop 62).
    min_top_above_tcp = 0.010
    tip_clearance = 0.012
    align_tolerance = 0.01  # m horizontal error at which the pads' tips may reach the object's top
    funnel_slope = 0.5  # m of horizontal error allowed per m of height above that
    at_grasp_tolerance = 0.008  # m from the grasp point under which it closes
    keep_closing_within = 0.02  # m from the grasp point under which it keeps closing once begun
    # Cartesian speed per phase (m per 20 ms control step): fast in free space, slow near the
    # object so that the arm's few steps of tracking lag do not overshoot into it.
    place_funnel = 0.03  # m from the goal within which the expert moves a carried object at the lowering speed
    descent_slope = 1.5  # m of height above the table per m from the goal, carrying
    place_tolerance = 0.012  # m from the goal within which it lets go (success: 0.02)
    # m: the least step toward a target further away, so that an imitating policy is shown a
    # clear direction, not a vanishing one, over the last millimetres: it stalled there at 2 mm
    # (about 0.1 of an action, what its fit is off by).
    min_step = 0.005
    release_height = 0.006  # m above its rest under which a carried object is let go
    release_margin = 0.008  # m of opening over the object's width before the letting-go hand rises
    fully_open_share = 0.95  # of the stroke: open enough to rise whatever the object
    keep_releasing_within = 0.018  # m from the goal within which letting go, once begun, goes on
    # m above the table over which a carried object rises at the lift's speed, not the carry's:
    # at 8 mm a step from a standstill the FR3's arm (110 N m shoulder) snatched a 52 mm box up
    # faster than the pads held it, and it turned out of them (9 of 30 placements knocked over).
    gentle_lift_height = 0.05
    # The arm whose span (RobotSpec.arm_span) the speeds were tuned for. A shorter arm carries
    # slower, in proportion (its cell is as much smaller: the episode keeps its pace): the FR3's
    # weaker shoulder still shook objects out of the pads at 8 mm a step (6 of 100 knocked over in
    # the training world with the gentle lift). A longer arm keeps these speeds: at 6 mm the
    # FR10's long carries ran out of time (8 of 100, against 2).
    speeds_tuned_on = DEFAULT_ROBOT
    phase_speed = {"hover": 0.015, "descend": 0.006, "close": 0.006, "lift": 0.006,
                   "carry": 0.008, "lower": 0.004, "release": 0.004, "retreat": 0.008}

    def __init__(self, env) -> None:
        self.env: FR5Env = env.unwrapped
        spec = self.env.robot_spec
        _, home_rotation = self.env.kinematics.tcp_pose(spec.home_joint_positions)
        # Keep the home pose's tcp yaw: only the approach axis matters to the tasks.
        self._down_rotation = home_rotation.ravel().tolist()
        # The arm's own kinematics, not PyBullet's solver: converged (PyBullet's left 1-4 mm of
        # each step undone) and 4-5x cheaper, which matters where the expert replays thousands of
        # starts (the reverse curriculum).
        self._inverse = InverseKinematics(self.env.kinematics)
        self._max_step = self.env.cfg.action.max_joint_step
        # The arm's action as a tcp step (action.space: tcp) rather than joint increments.
        self._tcp_space = self.env.cfg.action.space == "tcp"
        self._carry_speed = self.phase_speed["carry"] * min(1.0, spec.arm_span / load_robot_spec(self.speeds_tuned_on).arm_span)
        self.phase = "hover"

    def reset(self) -> None:
        """Nothing to forget (the expert is stateless); kept for a uniform actor interface."""
        self.phase = "hover"

    def act(self, observation: Optional[np.ndarray] = None) -> np.ndarray:
        """Next action in [-1, 1]^7 (the observation is unused: the expert reads the simulator)."""
        # Plain floats throughout (numpy's per-call cost on three-element vectors was half of each
        # call, and the reverse curriculum calls this for every step of every start it replays);
        # the arithmetic is numpy's, term by term, so the actions are the same to the bit.
        env = self.env
        state = env.task_state()
        q = state.joint_positions
        tcp_x, tcp_y, tcp_z = state.tcp_position
        object_x, object_y, object_z = state.object_position
        # The hand's yaw, once a step (forward kinematics): every phase's rotation keeps or turns it.
        hand_yaw = self._hand_yaw(state)
        grasp = env.task.name in ("grasp", "place")
        grasp_offset = self._grasp_offset() if grasp else 0.0
        grasp_z = object_z + grasp_offset
        dx, dy, dz = object_x - tcp_x, object_y - tcp_y, grasp_z - tcp_z  # to the grasp point
        horizontal_error = math.sqrt(dx * dx + dy * dy)
        # Held: both pads on it, and the fingers commanded closed or the object off the table (a
        # learner's half-open command on a lifted object is told to close, not to grasp anew).
        lifted = object_z - state.object_start_position[2] > 2.0 * self.release_height
        held = grasp and state.fingers_object_contact == 2 and (
            lifted or env.episode.gripper_command_width < env.robot_spec.max_opening_width / 2.0)
        placing = self._place_phase(state, held) if env.task.name == "place" else None
        if placing is not None:
            phase, target = placing
        elif held:
            phase = "lift"
            target = (object_x, object_y, state.object_start_position[2] + grasp_offset + self.lift_clearance)
        elif grasp and self._closing(math.sqrt(dx * dx + dy * dy + dz * dz)):
            phase, target = "close", (object_x, object_y, grasp_z)
        else:
            # Toward the object along a cone: the further off to the side, the higher above it
            # (2 m per m beyond align_tolerance; the pads' tips level with the top at
            # align_tolerance; the grasp point straight above it). A height that is a function of
            # the error, not a step from "hover up there" to "descend": a learner averaged the two
            # at the step and sank beside the object.
            top_above = self._top_above_grasp(grasp_offset)
            # A hand still turning to the object's yaw counts as off to the side by as much as the
            # turn moves a pad across the top (half its diagonal per radian): it came down while
            # turning and closed on a box's corners, 36 degrees off its faces.
            horizontal_error += self._corner_reach() * abs(self._yaw_error(state, hand_yaw))
            cone_height = grasp_z + top_above * min(1.0, horizontal_error / self.align_tolerance) \
                + max(horizontal_error - self.align_tolerance, 0.0) / self.funnel_slope
            target = (object_x, object_y, min(cone_height, object_z + self.hover_height))
            # Named (and timed) by the funnel: the higher the pads' tips above the top, the more
            # lateral error the straight line down removes on the way.
            aligned = horizontal_error < self.align_tolerance + self.funnel_slope * max(tcp_z - grasp_z - top_above, 0.0)
            phase = "descend" if aligned else "hover"
        self.phase = phase
        # Straight-line Cartesian motion: IK for a point a short step along the line, slowing
        # down over the last centimetres.
        offset_x, offset_y, offset_z = target[0] - tcp_x, target[1] - tcp_y, target[2] - tcp_z
        distance = math.sqrt(offset_x * offset_x + offset_y * offset_y + offset_z * offset_z)
        speed = self.phase_speed[phase]
        if phase in ("hover", "descend"):
            # Fast in free space, slow over the last centimetres, aligned or not.
            speed = self.phase_speed["hover" if tcp_z - grasp_z > 0.06 else "descend"]
        elif phase == "carry":
            speed = self._carry_speed
            if object_z - state.object_start_position[2] < self.gentle_lift_height:
                speed = min(speed, self.phase_speed["lift"])
        step = min(speed, max(0.35 * distance, min(distance, self.min_step)))
        if distance > step:
            fraction = step / distance
            target = (tcp_x + offset_x * fraction, tcp_y + offset_y * fraction, tcp_z + offset_z * fraction)
        gripper = -1.0 if phase in ("close", "lift", "carry", "lower") else 1.0
        wanted_rotation = self._rotation(state, phase, held, hand_yaw)
        if self._tcp_space:
            return self._tcp_action(hand_yaw, (target[0] - tcp_x, target[1] - tcp_y, target[2] - tcp_z),
                                    wanted_rotation, gripper)
        joint_targets = self._inverse_kinematics(target, q, wanted_rotation)
        max_step = self._max_step
        delta = [(wanted - angle) / max_step for wanted, angle in zip(joint_targets, q)]
        # Scale the whole joint step (not per joint) so the motion keeps its direction.
        scale = max(1.0, max(abs(value) for value in delta))
        return np.array([value / scale for value in delta] + [gripper], dtype=np.float32)

    def _tcp_action(self, current_yaw: float, translation: Sequence[float],
                    wanted_rotation: Optional[Sequence[float]], gripper: float) -> np.ndarray:
        """The action of ``action.space: tcp`` for a tcp step of ``translation`` (m, base_link) and
        a turn from ``current_yaw`` (rad, :meth:`_hand_yaw`) to the yaw of ``wanted_rotation`` (9
        floats, row-major; None: home's yaw), the arm part scaled whole to at most 1 so that the
        step keeps its direction; values 3 and 4 (not used by that space) 0."""
        wanted_yaw = yaw_of_rotation(self._down_rotation if wanted_rotation is None else wanted_rotation)
        cfg = self.env.cfg.action
        arm = [value / cfg.max_tcp_translation_step for value in translation] + [0.0, 0.0] + \
              [math.remainder(wanted_yaw - current_yaw, 2.0 * math.pi) / cfg.max_tcp_rotation_step]
        scale = max(1.0, max(abs(value) for value in arm))
        return np.array([value / scale for value in arm] + [gripper], dtype=np.float32)

    def _closing(self, to_grasp_point: float) -> bool:
        """Whether to close on the object from ``to_grasp_point`` (m) away: within
        ``at_grasp_tolerance``, or within ``keep_closing_within`` once the fingers were commanded
        to close (an observable state): an imitating policy that began to close a few millimetres
        early was told to open again, and it hovered between the two."""
        if to_grasp_point < self.at_grasp_tolerance:
            return True
        closing = self.env.episode.gripper_command_width < 0.9 * self.env.robot_spec.max_opening_width
        return closing and to_grasp_point < self.keep_closing_within

    def _letting_go(self, to_goal: float, above_rest: float) -> bool:
        """Whether letting go, once begun (the fingers commanded at least a quarter open: in the
        observation), goes on: within ``keep_releasing_within`` (m) of the goal and twice
        ``release_height`` above the table. A learner at the edge of the narrower band where a
        closed hand lets go was told to open and to close in turn, and hovered half open."""
        opening = self.env.episode.gripper_command_width >= 0.25 * self.env.robot_spec.max_opening_width
        return opening and above_rest <= 2.0 * self.release_height and to_goal <= self.keep_releasing_within

    def _fingers_clear_width(self, state) -> float:
        """m of measured opening at which the letting-go hand may rise: the object's footprint
        across the fingers' closing axis (the tcp's y) and ``release_margin``, or
        ``fully_open_share`` of the stroke, whichever is less. 90 % of the stroke alone (72 mm)
        was 2 mm over the grip on a 70 mm object: an imitating policy could not tell the two
        apart, rose while the fingers still held it, lifted it off the table and closed on it
        again (docs/experiments.md, stop 64)."""
        max_width = self.env.robot_spec.max_opening_width
        shape = self.env.episode.plant.object_shape
        if shape is None:
            return self.fully_open_share * max_width
        turn = yaw_of(state.object_quaternion) - self._hand_yaw(state)
        across = abs(math.cos(turn)) * shape.size[1] + abs(math.sin(turn)) * shape.size[0]
        return min(self.fully_open_share * max_width, across + self.release_margin)

    def _corner_reach(self) -> float:
        """m from the object's axis to its top's corners (0 without an object shape)."""
        shape = self.env.episode.plant.object_shape
        return 0.5 * math.hypot(shape.size[0], shape.size[1]) if shape is not None else 0.0

    def _symmetry_order(self) -> int:
        """The object's top's symmetry order (0: a cylinder, or no shape: its yaw does not matter)."""
        shape = self.env.episode.plant.object_shape
        return shape.symmetry_order if shape is not None else 0

    def _hand_yaw(self, state) -> float:
        """The tcp's yaw now (rad, base_link), from the measured joints."""
        return yaw_of_rotation(self.env.kinematics.tcp_pose(state.joint_positions)[1].ravel())

    def _grasp_yaw(self, state, hand_yaw: float) -> float:
        """The hand's yaw to grasp the object at (rad, base_link): of the yaws the top's symmetry
        makes equal, the nearest to the hand's own ``hand_yaw`` (the hand's own for a cylinder)."""
        order = self._symmetry_order()
        if order == 0:
            return hand_yaw
        period = 2.0 * math.pi / order
        object_yaw = yaw_of(state.object_quaternion)
        return object_yaw + period * round((hand_yaw - object_yaw) / period)

    def _yaw_error(self, state, hand_yaw: Optional[float] = None) -> float:
        """rad the hand has still to turn to grasp the object (0 for a cylinder); ``hand_yaw``:
        the tcp's yaw where the caller has it."""
        if self._symmetry_order() == 0:
            return 0.0
        hand_yaw = self._hand_yaw(state) if hand_yaw is None else hand_yaw
        return math.remainder(self._grasp_yaw(state, hand_yaw) - hand_yaw, 2.0 * math.pi)

    def _top_above_grasp(self, grasp_offset: float) -> float:
        """m the tcp is above the grasp point when the pads' tips reach the object's top (0
        without an object shape)."""
        shape = self.env.episode.plant.object_shape
        top = max(shape.size[2] / 2.0 - grasp_offset, 0.0) if shape is not None else 0.0
        return top + self.pad_tips_below_tcp

    def _grasp_offset(self) -> float:
        """m above the object's centre where the fingers close: ``grasp_height_offset``, but on a
        short object low enough that its top stands ``min_top_above_tcp`` above the tcp (no lower
        than ``tip_clearance`` over the table for the pads' tips), and on a tall one high enough
        that its top stays ``finger_reach`` short of the palm. Without a shape, ``grasp_height_offset``."""
        shape = self.env.episode.plant.object_shape
        if shape is None:
            return self.grasp_height_offset
        half_height = shape.size[2] / 2.0
        low = min(self.grasp_height_offset, half_height - self.min_top_above_tcp)
        return max(self.pad_tips_below_tcp + self.tip_clearance - half_height, low, half_height - self.finger_reach)

    def _place_phase(self, state, held: bool):
        """The place task's phases after the grasp, or None while grasping: carry the object above
        the goal (turning a box to the goal's yaw, :meth:`_rotation`), lower it onto the table,
        let go, and rise clear of it."""
        task = self.env.task
        goal_x, goal_y, _ = task.goal
        object_x, object_y, object_z = state.object_position
        start_z = state.object_start_position[2]
        to_goal = math.hypot(goal_x - object_x, goal_y - object_y)
        tcp_x, tcp_y, tcp_z = state.tcp_position
        if held:
            # Set down where the policy sees it: a learner cannot correct a slip it never sees, and
            # labels from the truth told it to move an object it saw on the goal (it froze there).
            seen = self._held_as_the_policy_sees()
            if seen is not None:
                object_x, object_y, object_z = seen
                to_goal = math.hypot(goal_x - object_x, goal_y - object_y)
        offset_x, offset_y = tcp_x - object_x, tcp_y - object_y  # the object's place in the hand
        if held:
            hand_over_goal = (goal_x + offset_x, goal_y + offset_y)
            above_rest = object_z - start_z
            rest_hand_z = tcp_z - above_rest  # where the hand is when the object stands on the table
            carry_z = rest_hand_z + self.lift_clearance
            if to_goal > 2.0 * self.lift_clearance / self.descent_slope and tcp_z < carry_z - 0.02:
                return "carry", (tcp_x, tcp_y, carry_z)  # far from the goal: up to the carry height first
            # A box still turning to the goal's yaw (beyond half the tolerance) counts as further
            # from the goal by as much as the carry moves while the hand turns the rest: a learner
            # a few steps behind on the turn was told to lower and let go, and set a box down 12
            # and 32 degrees off (docs/experiments.md, stop 69).
            turn_left = max(0.0, task.yaw_error(state) - 0.5 * task.yaw_tolerance)
            to_goal_turning = to_goal + self._carry_speed * turn_left / self.max_turn_step
            if not self._letting_go(to_goal, above_rest) and (above_rest > self.release_height or to_goal > self.place_tolerance
                                                               or turn_left > 0.0):
                # Over the goal along a cone: the nearer, the lower, down to 1 mm below the rest
                # (pressing further slides the object up into the palm). A cone, not a step from
                # carrying to lowering: an imitating policy averaged the two at the step and hovered.
                height = min(self.lift_clearance, self.descent_slope * max(0.0, to_goal_turning - self.place_tolerance / 2.0))
                phase = "carry" if to_goal_turning > self.place_funnel else "lower"
                return phase, (*hand_over_goal, rest_hand_z - 0.001 + height)
            return "release", (tcp_x, tcp_y, tcp_z)
        # Set down near the goal, or letting go with the object still in the pads a little above
        # the table: go on opening (re-grasping there was the other label a learner was given).
        if self._letting_go(to_goal, object_z - start_z) or (to_goal <= task.settings.position_tolerance and abs(object_z - start_z) < 0.005):
            if state.gripper_width < self._fingers_clear_width(state):
                return "release", (tcp_x, tcp_y, tcp_z)  # the fingers still opening
            return "retreat", (tcp_x, tcp_y, object_z + self.hover_height)
        return None

    def _held_as_the_policy_sees(self) -> Optional[Tuple[float, float, float]]:
        """The held object's centre (m, base_link) where the policy observes it, when the episode
        models the tracker's hold (``randomisation.target_in_hand_from_grasp``: fixed in the tcp
        frame from the grasp); None where the policy sees the truth."""
        target = self.env.episode.chain.target
        in_tcp = None if target is None else target.held_in_tcp
        if in_tcp is None:
            return None
        position, rotation = self.env.episode.tcp_pose()
        held = np.asarray(position) + np.asarray(rotation) @ in_tcp
        return float(held[0]), float(held[1]), float(held[2])

    def _inverse_kinematics(self, tcp_target: Sequence[float], start: Sequence[float],
                            rotation: Optional[Sequence[float]] = None) -> List[float]:
        """Joint angles (rad) that put the tcp at ``tcp_target`` (m, base_link) with ``rotation``
        (9 floats, row-major; None: pointing down at home's yaw), found from ``start`` (the
        measured joints, rad); the last iterate if not converged (the action then scales it to one
        step all the same)."""
        joints, _ = self._inverse.solve(start, tcp_target, self._down_rotation if rotation is None else rotation)
        return joints

    def _rotation(self, state, phase: str, held: bool, tcp_yaw: float) -> Sequence[float]:
        """The tcp rotation to aim for: pointing down, turned about the vertical so the fingers
        close across a box's narrower side (its own x along the gripper's x), and, carrying it
        in the place task, so that the box stands at the goal's yaw. A cylinder needs no turn:
        the hand keeps its yaw, as it does letting go and rising clear.

        :param tcp_yaw: the tcp's yaw now (rad; :meth:`_hand_yaw`)."""
        order = self._symmetry_order()
        home_yaw = math.atan2(self._down_rotation[3], self._down_rotation[0])
        if phase in ("release", "retreat") or order == 0:
            # Letting go and rising clear, and whatever the phase for a cylinder (its yaw does not
            # matter): keep the hand's yaw. Turned back to home's, a learner had to read home's
            # yaw off the joints, and it turned the hand to and fro over a cylinder it descended on.
            wanted = tcp_yaw
        elif held and self.env.task.name == "place" and phase in ("carry", "lower"):
            # The object turns with the hand: turn the hand by the object's yaw error to the goal.
            period = 2.0 * math.pi / order
            error = (self.env.task.goal[2] - yaw_of(state.object_quaternion)) % period
            error = error - period if error > period / 2.0 else error
            wanted = tcp_yaw + error
        else:
            # hover, descend, close, lift: of the yaws the top's symmetry makes equal, the nearest
            # to the hand's own: what the observation's (sin kΔ, cos kΔ) tells apart. Nearest to
            # home's, the label asked a hand that had turned the other way to turn a quarter back
            # over a square it was already aligned with, and the learner froze.
            wanted = self._grasp_yaw(state, tcp_yaw)
        # At most max_turn_step a step: a large turn scaled the whole joint step down (the wrist's
        # share decides the scale) and left the translation a few hundredths of an action; where
        # the turn's direction flips (half a period off, either way is as near) a learner
        # averaged the two turns to nothing, and with them the translation, and froze.
        change = math.remainder(wanted - tcp_yaw, 2.0 * math.pi)
        wanted = tcp_yaw + max(-self.max_turn_step, min(self.max_turn_step, change))
        turn = wanted - home_yaw
        cosine, sine = math.cos(turn), math.sin(turn)
        r = self._down_rotation
        # Rz(turn) @ R_home, row-major.
        return [cosine * r[0] - sine * r[3], cosine * r[1] - sine * r[4], cosine * r[2] - sine * r[5],
                sine * r[0] + cosine * r[3], sine * r[1] + cosine * r[4], sine * r[2] + cosine * r[5],
                r[6], r[7], r[8]]
