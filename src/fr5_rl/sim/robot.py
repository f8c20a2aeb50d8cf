"""The FR5 with its gripper in a PyBullet world: loading, joint maps, commands, state."""
from __future__ import annotations

import hashlib
import re
import tempfile
from pathlib import Path
from typing import Dict, List, NamedTuple, Optional, Sequence, Tuple

import numpy as np
from .bullet import p

from ..config import RobotSpec, package_root, urdf_path
from ..env_config import SimulationConfig


# The generator's massless root (tools/generate_description.py ROOT_LINK_XML), one line each.
_WORLD_ROOT = re.compile(r'^  <link name="world"/>\n|^  <joint name="world_joint" type="fixed">.*\n', re.MULTILINE)


def urdf_for_pybullet(robot: str) -> str:
    """Path of a copy of an arm's URDF that PyBullet can load.

    :param robot: the arm's name (``urdf/<robot>.urdf``).

    PyBullet does not resolve ``package://fr5_rl/`` mesh URIs, so the copy has them replaced by
    the package root. The massless ``world`` root that robot_state_publisher needs is left out:
    PyBullet's fixed base is ``base_link`` itself. The copy is cached in the temp directory under
    a content hash.
    """
    root = package_root()
    path = urdf_path(robot)
    if not path.is_file():
        raise FileNotFoundError(f"{path} is missing; regenerate it with `make meshes`")
    text = path.read_text(encoding="utf-8").replace("package://fr5_rl/", f"{root}/")
    text = _WORLD_ROOT.sub("", text)
    digest = hashlib.sha1(text.encode("utf-8")).hexdigest()[:16]
    resolved = Path(tempfile.gettempdir()) / f"fr5_rl_{digest}.urdf"
    if not resolved.is_file():
        tmp = resolved.with_suffix(f".{id(text)}.tmp")
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(resolved)  # atomic: parallel workers may race here
    return str(resolved)


# The collision filter group of the robot's links: one bit that no body has by default (Bullet's
# defaults use the lowest bits: 1 dynamic, 2 static).
_ROBOT_LINKS_COLLISION_GROUP = 1 << 6


def cap_joint_speeds(body: int, robot: RobotSpec, client: int) -> None:
    """Cap the speed of every joint of ``body`` at the fastest arm joint's rated speed (rad/s,
    read as m/s by the fingers).

    PyBullet holds one speed cap per body, not one per joint: ``changeDynamics(maxJointVelocity=)``
    sets the multibody's cap on every coordinate, and the last call wins (a cap given per joint,
    fingers last, held the whole arm at the fingers' 0.08 m/s). With the fastest rated speed no
    joint is held below its own. Each joint's own limit is kept where it is set: the commands
    (the action scaling, the safety gate) never ask a joint for more, and the fingers' target
    ramps at the gripper's rated speed (:meth:`FR5Robot.command`).

    :param body: PyBullet body id of the robot, in ``client``.
    :param robot: the arm's rated limits (config/robots/<arm>.yaml).
    :param client: PyBullet client id.
    """
    p.changeDynamics(body, -1, maxJointVelocity=float(max(robot.velocity_limits)), physicsClientId=client)


_new_tuple = tuple.__new__
# N the linkage between the fingers may exert to keep them mirrored: several times the grip (at
# most 140 N), as stiff as a mechanism next to the motor's limited squeeze.
_FINGER_COUPLING_FORCE = 1000.0

class Measurement(NamedTuple):
    """One read of the arm (two simulator queries, plain floats: the step path).

    :param joint_positions: arm angles (rad), controller order.
    :param joint_velocities: arm rates (rad/s).
    :param gripper_width: opening width (m), the sum of both fingers' travel.
    :param tcp_position: (x, y, z) of the tcp in base_link (m), as the simulator computes it.
    :param tcp_quaternion: (x, y, z, w) of the tcp frame in base_link.
    """

    joint_positions: List[float]
    joint_velocities: List[float]
    gripper_width: float
    tcp_position: Tuple[float, float, float]
    tcp_quaternion: Tuple[float, float, float, float]


class FR5Robot:
    """FR5 arm + PGI-140-80 gripper under position control, as the real driver exposes it.

    Joint positions are in rad (controller order ``j1`` … ``j6``); the gripper is commanded as
    an opening width in metres, split evenly between the two mirrored fingers.
    """

    def __init__(self, client: int, robot: RobotSpec, sim_cfg: SimulationConfig) -> None:
        self.client = client
        self.spec = robot
        self.body = p.loadURDF(
            urdf_for_pybullet(robot.model), basePosition=[0, 0, 0], useFixedBase=True,
            flags=p.URDF_USE_INERTIA_FROM_FILE, physicsClientId=client,
        )
        joint_index: Dict[str, int] = {}
        link_index: Dict[str, int] = {}
        for index in range(p.getNumJoints(self.body, physicsClientId=client)):
            info = p.getJointInfo(self.body, index, physicsClientId=client)
            joint_index[info[1].decode()] = index
            link_index[info[12].decode()] = index
        try:
            self.arm_joints = [joint_index[name] for name in robot.joint_names]
            self.finger_joints = [joint_index[name] for name in robot.finger_joint_names]
            self.tcp_link = link_index[robot.tcp_frame]
        except KeyError as missing:
            raise RuntimeError(f"urdf/{robot.model}.urdf lacks joint or link {missing}; regenerate it "
                               "with `make meshes`") from None
        self.all_joints = self.arm_joints + self.finger_joints
        self.link_index = link_index
        self.finger_links = {index for index in self.finger_joints}
        n_arm = self._n_arm = len(self.arm_joints)
        # One motor call for all eight joints: per-joint forces and gains in one list each.
        # Grip force (N) the simulated gripper squeezes with: the PGI-140-80 is set between
        # 40 and 140 N; a 0.1 kg object needs little, and less force keeps contacts stable.
        grip_force = min(sim_cfg.gripper_force, robot.finger_effort)
        self._forces = robot.effort_limits.tolist() + [grip_force] * 2
        self._position_gains = [sim_cfg.arm_position_gain] * n_arm + [sim_cfg.finger_position_gain] * 2
        self._velocity_gains = [sim_cfg.arm_velocity_gain] * n_arm + [1.0, 1.0]
        self._finger_travel = robot.finger_travel
        # The gripper moves its fingers at its rated speed: the target ramps at most this far
        # per command (one control period).
        self._finger_velocity = robot.finger_velocity
        self._finger_step = robot.finger_velocity * sim_cfg.control_dt
        self._finger_target = robot.finger_travel
        self._joint_damping: Optional[float] = None  # unknown until set
        cap_joint_speeds(self.body, robot, client)
        self._keep_links_out_of_each_others_pairs()
        if sim_cfg.fingers_coupled:
            self._couple_fingers()

    def _couple_fingers(self) -> None:
        # The PGI-140-80 drives both fingers from one motor through a linkage: they move as a
        # mirrored pair, so a held object stays centred between them. Two independently
        # force-limited fingers, both squeezing at their limit, let the pair and the object drift
        # together along the closing axis with nothing to bring them back: 7 mm (median) to 20 mm
        # in a carry (docs/experiments.md, stop 63). A gear constraint keeps the two travels equal.
        left, right = self.finger_joints
        constraint = p.createConstraint(self.body, left, self.body, right, jointType=p.JOINT_GEAR,
                                        jointAxis=[0, 1, 0], parentFramePosition=[0, 0, 0],
                                        childFramePosition=[0, 0, 0], physicsClientId=self.client)
        p.changeConstraint(constraint, gearRatio=-1, erp=0.2, maxForce=_FINGER_COUPLING_FORCE,
                           physicsClientId=self.client)

    def _keep_links_out_of_each_others_pairs(self) -> None:
        # Loaded without self-collision, the robot's links never touch one another, yet Bullet's
        # broadphase still pairs every two whose boxes overlap and rejects the pair later, at
        # every physics step. A collision group of the links' own, which their masks leave out,
        # stops those pairs at the broadphase (PyBullet pairs two bodies when either one's group
        # meets the other's mask): the same contacts, 3-8 % off an env step (docs/experiments.md).
        # Every other body keeps Bullet's default group and mask and still pairs with every link.
        # The base keeps its defaults too: it is static, as the table is, and must not pair with it.
        for link in range(p.getNumJoints(self.body, physicsClientId=self.client)):
            p.setCollisionFilterGroupMask(self.body, link, _ROBOT_LINKS_COLLISION_GROUP, ~_ROBOT_LINKS_COLLISION_GROUP,
                                          physicsClientId=self.client)

    def stand_on(self, body: int) -> None:
        """Mount the robot on ``body`` (the table): its base and first link never count as
        touching it, since they stand on it.

        :param body: PyBullet body id of what the robot stands on, in this robot's client.
        """
        for link in (-1, 0):  # the base and the first link
            p.setCollisionFilterPair(self.body, body, link, -1, 0, physicsClientId=self.client)

    # ------------------------------------------------------------------ commands
    def reset(self, joint_positions: np.ndarray, opening_width: float) -> None:
        """Teleport to a configuration at rest and hold it (start of an episode)."""
        finger = opening_width / 2.0
        positions = [[float(angle)] for angle in joint_positions] + [[finger]] * len(self.finger_joints)
        p.resetJointStatesMultiDof(self.body, self.all_joints, positions, targetVelocities=[[0.0]] * len(positions),
                                   physicsClientId=self.client)
        self._finger_target = finger
        self.command(joint_positions, opening_width)

    def command(self, joint_targets: Sequence[float], opening_width: float, period: Optional[float] = None) -> None:
        """Send position targets: arm (rad, controller order) and gripper opening width (m).

        ``period`` (s) is how long this command stands before the next one (default: one
        control period); the finger targets ramp at the gripper's rated speed over it.
        """
        wanted = min(max(opening_width / 2.0, 0.0), self._finger_travel)
        limit = self._finger_step if period is None else self._finger_velocity * period
        finger = self._finger_target + min(max(wanted - self._finger_target, -limit), limit)
        self._finger_target = finger
        targets = [*joint_targets, finger, finger]
        p.setJointMotorControlArray(
            self.body, self.all_joints, p.POSITION_CONTROL, targetPositions=targets,
            forces=self._forces, positionGains=self._position_gains, velocityGains=self._velocity_gains,
            physicsClientId=self.client,
        )

    def save_command_state(self) -> Tuple[float, Optional[float]]:
        """What the simulator's saved state does not hold: the fingers' ramped target (m) and
        the joint damping set (N*m*s/rad), for :meth:`restore_command_state`."""
        return self._finger_target, self._joint_damping

    def restore_command_state(self, state: Tuple[float, Optional[float]]) -> None:
        """Back to :meth:`save_command_state`'s values (the damping is re-applied if it differs)."""
        self._finger_target, damping = state
        if damping is not None:
            self.set_joint_damping(damping)

    def set_joint_damping(self, damping: float) -> None:
        """Viscous damping (N*m*s/rad) on every arm joint (domain randomisation)."""
        if damping == self._joint_damping:
            return  # six simulator calls saved at every reset of an env without randomisation
        for index in self.arm_joints:
            p.changeDynamics(self.body, index, jointDamping=float(damping), physicsClientId=self.client)
        self._joint_damping = damping

    # ------------------------------------------------------------------ state
    def measure(self) -> Measurement:
        """One read of the robot, in two simulator queries and plain floats (the step path).

        Returns :meth:`joint_lists` and the tcp position (m) and quaternion (x, y, z, w) in
        base_link as the simulator computes them (:class:`Measurement`). Equal to
        :class:`fr5_rl.kinematics.ForwardKinematics` (the ROS node's FK) to < 1e-6 m; the test
        suite checks it.
        """
        positions, velocities, width = self.joint_lists()
        link = p.getLinkState(self.body, self.tcp_link, computeForwardKinematics=1, physicsClientId=self.client)
        # tuple.__new__: the named tuple without its Python-level constructor (the step path).
        return _new_tuple(Measurement, (positions, velocities, width, link[4], link[5]))

    def joint_lists(self) -> Tuple[List[float], List[float], float]:
        """Measured arm positions (rad), velocities (rad/s), controller order, and gripper
        opening width (m), as plain floats from one simulator query."""
        states = p.getJointStates(self.body, self.all_joints, physicsClientId=self.client)
        positions, velocities, _, _ = zip(*states)  # each joint: position, velocity, forces, torque
        n_arm = self._n_arm
        return list(positions[:n_arm]), list(velocities[:n_arm]), sum(positions[n_arm:])  # two fingers

    def joint_state(self) -> Tuple[np.ndarray, np.ndarray, float]:
        """:meth:`joint_lists` as arrays."""
        positions, velocities, width = self.joint_lists()
        return np.array(positions), np.array(velocities), width

    def joint_lists_with_fingers(self) -> Tuple[List[float], List[float]]:
        """Measured positions and velocities of all eight joints, as plain floats from one
        simulator query: the arm (rad, rad/s, controller order j1 .. j6), then the two
        fingers (m, m/s, each finger's travel from closed, in ``finger_joint_names`` order)."""
        states = p.getJointStates(self.body, self.all_joints, physicsClientId=self.client)
        positions, velocities, _, _ = zip(*states)
        return list(positions), list(velocities)

    def tcp_pose_from_simulator(self) -> Tuple[np.ndarray, np.ndarray]:
        """tcp position (m) and 3x3 rotation in base_link, as the simulator computes them."""
        state = p.getLinkState(self.body, self.tcp_link, computeForwardKinematics=1, physicsClientId=self.client)
        rotation = np.array(p.getMatrixFromQuaternion(state[5])).reshape(3, 3)
        return np.array(state[4]), rotation

    def contacts(self) -> list:
        """All contact points (PyBullet tuples) of the robot found by the last physics step."""
        return p.getContactPoints(bodyA=self.body, physicsClientId=self.client)

    def comes_within(self, body: int, distance: float) -> bool:
        """Whether any link of the arm or gripper lies closer than ``distance`` (m) to ``body``
        where they stand now (no physics step needed: for checking a placement)."""
        return len(p.getClosestPoints(bodyA=self.body, bodyB=body, distance=float(distance),
                                      physicsClientId=self.client)) > 0
