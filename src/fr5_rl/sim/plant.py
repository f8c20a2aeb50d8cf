"""The physical plant: the arm, its gripper, the table and the object, as typed states.

:class:`Plant` is the one door to the simulated cell for everything above :mod:`fr5_rl.sim`:
it advances physics, commands the joints and reads states back as named tuples in
``base_link``. No PyBullet id or tuple leaves it.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import List, NamedTuple, Optional, Sequence, Tuple

import numpy as np

from ..config import RobotSpec
from ..draws import EpisodeDraws
from ..objects import ObjectShape
from ..env_config import EnvConfig, SimulationConfig
from .robot import FR5Robot, Measurement
from .world import PyBulletWorld

__all__ = ["Contacts", "JointStates", "Measurement", "Plant", "Pose", "SceneDescription"]


_new_tuple = tuple.__new__
OUT_OF_THE_WORLD = (0.0, 0.0, -10.0)  # m, base_link: where an object taken off the table waits

class JointStates(NamedTuple):
    """Measured state of the eight joints, by name, as ``sensor_msgs/JointState`` carries it.

    :param names: the arm joints ``j1`` .. ``j6`` (controller order), then the two finger joints.
    :param positions: arm angles (rad), then each finger's travel from closed (m; the opening
        width is their sum).
    :param velocities: arm (rad/s), then fingers (m/s).
    """

    names: Tuple[str, ...]
    positions: Tuple[float, ...]
    velocities: Tuple[float, ...]


class Pose(NamedTuple):
    """A pose in a named frame.

    :param position: (x, y, z) in metres.
    :param quaternion: (x, y, z, w), unit.
    :param frame_id: the frame both are expressed in (``base_link`` here).
    """

    position: Tuple[float, float, float]
    quaternion: Tuple[float, float, float, float]
    frame_id: str


class Contacts(NamedTuple):
    """What the robot touches after the last physics step.

    :param table: some link of the arm or gripper touches the table (its base never counts).
    :param arm_object: a link other than a finger touches the object.
    :param finger_pads: how many fingers (0, 1 or 2) touch the object.
    """

    table: bool
    arm_object: bool
    finger_pads: int


@dataclass(frozen=True)
class SceneDescription:
    """The static scene of the current episode, for drawing it (e.g. rviz markers).

    :param frame_id: the frame of every position below (``base_link``, the world frame).
    :param table_size: table box (x, y, thickness) in metres.
    :param table_center: centre (m) of the table box.
    :param table_top_height: z (m) of the table's top face.
    :param object_shape: ``"cylinder"`` or ``"box"``.
    :param object_dims: as placed this episode (after any size randomisation): (radius,
        height) of a cylinder, (half_extent,) of a cube or (half_x, half_y, half_z) of a box, metres.
    :param object_rest_z: z (m) of the object's centre when it stands on the table.
    :param goal: where the episode's object is to be set down, (x, y, yaw) (m, m, rad), for a task
        with a goal; else None.
    """

    frame_id: str
    table_size: Tuple[float, float, float]
    table_center: Tuple[float, float, float]
    table_top_height: float
    object_shape: str
    object_dims: Tuple[float, ...]
    object_rest_z: float
    goal: Optional[Tuple[float, float, float]] = None

    @property
    def object_description(self) -> ObjectShape:
        """The object's kind and size (m, along its own x, y and z axes: a box's longer top side on x)."""
        return ObjectShape.from_dims(self.object_shape, self.object_dims)

    @property
    def object_size(self) -> Tuple[float, float, float]:
        """Extent (m) of the object along its own x, y and z axes (its bounding box)."""
        return self.object_description.size


class Plant:
    """The simulated cell: one PyBullet world with the table, the arm and gripper, the object.

    :param cfg: the environment's configuration (table, object shape).
    :param robot: the arm (config/robots/<arm>.yaml).
    :param sim_cfg: the physics settings (the task's, ``EnvConfig.simulation_for``).
    :param gui: open PyBullet's window (needs an X display).
    :param renders: keep the TinyRenderer for :meth:`render` (slower to build objects).
    """

    def __init__(self, cfg: EnvConfig, robot: RobotSpec, sim_cfg: SimulationConfig, gui: bool = False,
                 renders: bool = False) -> None:
        self.cfg, self.spec = cfg, robot
        self.world = PyBulletWorld(sim_cfg, gui=gui, renders=renders)
        self.world.add_table(cfg.table)
        self.robot = FR5Robot(self.world.client, robot, sim_cfg)
        self.robot.stand_on(self.world.table_id)  # its base never counts as touching the table
        # The step path's calls, bound straight to the simulator's (no wrapper call at every
        # physics step): command(arm_targets, gripper_width, period=None), step_physics(),
        # step_period() and measure() -> Measurement, documented on FR5Robot and PyBulletWorld.
        self.command = self.robot.command
        self.step_physics = self.world.step_physics
        self.step_period = self.world.step
        self.measure = self.robot.measure
        self.joint_state_names = tuple(robot.joint_names) + tuple(robot.finger_joint_names)
        self.object_kind = cfg.object.shape  # set per episode (set_object)
        self.object_dims: Tuple[float, ...] = ()
        self.object_shape: Optional[ObjectShape] = None
        self.object_rest_z = cfg.table.top_height
        self._held = None  # hold_object's constraint, or None
        self._neighbours: List[Tuple[int, ObjectShape]] = []  # the other objects of a scene: (body, shape)

    # ------------------------------------------------------------------ the episode's scene
    def build_scene(self, draws: EpisodeDraws, start: Sequence[float], control_dt: float) -> Tuple[float, float, float]:
        """This episode's scene as drawn: a new object where the draws put it, the arm's damping,
        the physics step, and the arm teleported to ``start`` (rad) with the gripper open.

        :param control_dt: s per control period (the physics step divides it).
        :return: the object's centre (m, base_link).
        """
        self.set_object(draws.object_shape, draws.object_dims, draws.object_mass, draws.object_friction,
                        draws.object_rest_z)
        self.set_joint_damping(draws.joint_damping)
        self.set_physics_dt(draws.physics_dt, control_dt)
        placed = self.place_object(draws.object_xy, draws.object_yaw)
        self.reset_arm(start, self.spec.max_opening_width)
        return placed

    def set_object(self, shape: str, dims: Tuple[float, ...], mass: float, friction: float, rest_z: float) -> None:
        """A new object (every episode).

        :param shape: ``cylinder`` or ``box``.
        :param dims: (radius, height) of a cylinder, (half_extent,) of a cube or (half_x, half_y,
            half_z) of a box, metres.
        :param mass: kg. :param friction: lateral friction coefficient.
        :param rest_z: z (m, base_link) of its centre standing on the table.
        """
        self.world.set_object(shape, dims, mass, friction)
        self.object_kind, self.object_dims, self.object_rest_z = shape, dims, rest_z
        self.object_shape = ObjectShape.from_dims(shape, dims)

    def place_object(self, xy: Sequence[float], yaw: float) -> Tuple[float, float, float]:
        """Stand the object on the table at ``xy`` (m, base_link) with ``yaw`` (rad).

        :return: its centre (m, base_link).
        """
        position = (float(xy[0]), float(xy[1]), self.object_rest_z)
        self.world.place_object(position, yaw=float(yaw))
        return position

    def set_neighbours(self, bodies: Sequence[Tuple[ObjectShape, float, float, Sequence[float], Sequence[float]]]) -> None:
        """The scene's other objects, beside this episode's (the one the task judges): each
        ``(shape, mass, friction, position, quaternion)`` (kg; m and (x, y, z, w) in base_link),
        at rest. Those of the last call are removed first; ``[]`` leaves the object alone."""
        for body, _ in self._neighbours:
            self.world.remove_body(body)
        self._neighbours = []
        for shape, mass, friction, position, quaternion in bodies:
            body = self.world.add_body(shape.kind, shape.dims, mass, friction, color=(0.2, 0.45, 0.9, 1.0))
            self.world.place_body(body, position, quaternion)
            self._neighbours.append((body, shape))

    def take_off_table(self, neighbours: Sequence[int], the_object: bool = False) -> None:
        """Take objects away, as an operator clears what a cell cannot use: the scene's other
        objects at these indices (the order of :meth:`set_neighbours`) and, with ``the_object``,
        the episode's own (set aside out of the world, asleep, until the next episode places it)."""
        gone = set(neighbours)
        for index in sorted(gone, reverse=True):
            body, _ = self._neighbours.pop(index)
            self.world.remove_body(body)
        if the_object and self.world.object_id is not None:
            self.world.place_object(OUT_OF_THE_WORLD, yaw=0.0)

    @property
    def neighbour_shapes(self) -> List[ObjectShape]:
        """The scene's other objects' kinds and sizes, in the order given to :meth:`set_neighbours`."""
        return [shape for _, shape in self._neighbours]

    def neighbour_poses(self) -> List[Pose]:
        """Where the scene's other objects are now (ground truth, base_link), in the order given."""
        return [_new_tuple(Pose, (*self.world.body_pose(body), self.spec.base_frame)) for body, _ in self._neighbours]

    def object_near_arm(self, clearance: float) -> bool:
        """Whether a link of the arm or gripper lies within ``clearance`` (m) of the object as
        they stand now (no physics step: for checking a placement)."""
        return self.robot.comes_within(self.world.object_id, clearance)

    def set_joint_damping(self, damping: float) -> None:
        """Viscous damping (N*m*s/rad) on every arm joint."""
        self.robot.set_joint_damping(damping)

    def set_physics_dt(self, physics_dt: float, control_dt: float) -> None:
        """Change the physics step (s), if it differs; the substeps per period follow."""
        if physics_dt != self.world.physics_dt:
            self.world.set_physics_dt(physics_dt, control_dt)

    def reset_arm(self, joint_positions: Sequence[float], opening_width: float) -> None:
        """Teleport the arm to ``joint_positions`` (rad) at rest, gripper open to ``opening_width`` (m)."""
        self.robot.reset(joint_positions, opening_width)

    # ------------------------------------------------------------------ physics
    @property
    def physics_dt(self) -> float:
        """Duration (s) of one physics step."""
        return self.world.physics_dt

    @property
    def substeps(self) -> int:
        """Physics steps per control period."""
        return self.world.substeps

    # ------------------------------------------------------------------ states
    def contacts(self) -> Contacts:
        """What the robot touches (one simulator query for all of its contacts)."""
        table, obj, finger_links = self.world.table_id, self.world.object_id, self.robot.finger_links
        table_contact = arm_object_contact = False
        pads = set()
        for contact in self.robot.contacts():
            if contact[2] == table:
                table_contact = True
            elif contact[2] == obj:
                if contact[3] in finger_links:
                    pads.add(contact[3])
                else:
                    arm_object_contact = True
        return _new_tuple(Contacts, (table_contact, arm_object_contact, len(pads)))  # no Python-level constructor

    def object_pose(self) -> Pose:
        """The object's centre and orientation in base_link (ground truth)."""
        position, quaternion = self.world.object_pose()
        return _new_tuple(Pose, (position, quaternion, self.spec.base_frame))

    def joint_positions(self) -> np.ndarray:
        """Measured arm joint angles (rad), controller order."""
        return self.robot.joint_state()[0]

    def joint_states(self) -> JointStates:
        """Positions and velocities of the six arm joints and both fingers, by name (one query)."""
        positions, velocities = self.robot.joint_lists_with_fingers()
        return JointStates(self.joint_state_names, tuple(positions), tuple(velocities))

    def tcp_position(self) -> np.ndarray:
        """tcp position (m, base_link), from the simulator."""
        return self.robot.tcp_pose_from_simulator()[0]

    def scene(self) -> SceneDescription:
        """The table and this episode's object, in base_link (no simulator query)."""
        table = self.cfg.table
        sx, sy, thickness = table.size
        cx, cy = table.center_xy
        top = table.top_height
        return SceneDescription(
            frame_id=self.spec.base_frame, table_size=(sx, sy, thickness),
            table_center=(cx, cy, top - thickness / 2.0), table_top_height=top,
            object_shape=self.object_kind, object_dims=tuple(float(d) for d in self.object_dims),
            object_rest_z=self.object_rest_z,
        )

    # ------------------------------------------------------------------ hand-over
    def hold_object(self, object_in_tcp: Sequence[float]) -> None:
        """Fix the object in the gripper, its centre at ``object_in_tcp`` (m, tcp frame), as a
        person's hand-over into the closed gripper leaves it. :meth:`release_object` lets go."""
        from .held_object import HeldObject

        self.release_object()
        self.world.wake_object()
        self._held = HeldObject(self.world.client, self.robot.body, self.robot.tcp_link, self.world.object_id,
                                [self.world.table_id])
        self._held.hold(object_in_tcp)

    def release_object(self) -> None:
        """Let go of an object held by :meth:`hold_object` (nothing if none is)."""
        held, self._held = self._held, None
        if held is not None:
            held.release()

    # ------------------------------------------------------------------ saved states, pictures
    def save_state(self) -> Tuple[Tuple[int, bool], Tuple[float, Optional[float]]]:
        """The simulation as it stands (same bodies) and the robot's command state."""
        return self.world.save_state(), self.robot.save_command_state()

    def restore_state(self, saved: Tuple[Tuple[int, bool], Tuple[float, Optional[float]]]) -> None:
        """Back to :meth:`save_state`'s state (it stays saved)."""
        self.world.restore_state(saved[0])
        self.robot.restore_command_state(saved[1])

    def discard_state(self, saved: Tuple[Tuple[int, bool], Tuple[float, Optional[float]]]) -> None:
        """Free the simulator memory of a saved state."""
        self.world.discard_state(saved[0])

    def render(self) -> np.ndarray:
        """An RGB picture (H, W, 3) of the cell from a fixed camera."""
        return self.world.render()

    def close(self) -> None:
        """Disconnect from the simulator (safe twice)."""
        self.world.close()
