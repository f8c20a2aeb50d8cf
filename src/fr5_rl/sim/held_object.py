"""The object fixed in the closed gripper, for the camera's hand-eye calibration in simulation:
on a real arm a person hands the cup to the gripper and closes it; here a PyBullet fixed
constraint holds it where such a hand-over would leave it.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
from .bullet import p

from ..transforms import quaternion_from_matrix

# The cup stands upright when the tcp points down: its z axis is the tcp's reversed.
_CUP_IN_TCP = np.diag([1.0, -1.0, -1.0])


class HeldObject:
    """Fixes a world's object to a robot's tcp link until :meth:`release`.

    :param client: the PyBullet client of the world.
    :param robot_body: the robot's body id. :param tcp_link: its tcp link index.
    :param object_body: the object's body id.
    :param others: bodies the held object must not collide with (the table): a held cup is the
        hand's, and contacts would fight the constraint.
    """

    def __init__(self, client: int, robot_body: int, tcp_link: int, object_body: int,
                 others: Sequence[int] = ()) -> None:
        self.client, self.robot, self.tcp_link, self.object = client, robot_body, tcp_link, object_body
        self.others = list(others)
        self.constraint = -1

    def hold(self, object_in_tcp: Sequence[float]) -> None:
        """Put the object's centre at ``object_in_tcp`` (m, tcp frame), upright for a tcp pointing
        down, and fix it there; the fingers no longer collide with it (they close around it)."""
        state = p.getLinkState(self.robot, self.tcp_link, computeForwardKinematics=1, physicsClientId=self.client)
        tcp_position, tcp_quaternion = np.asarray(state[4]), state[5]
        tcp_rotation = np.asarray(p.getMatrixFromQuaternion(tcp_quaternion)).reshape(3, 3)
        offset = np.asarray(object_in_tcp, dtype=np.float64)
        position = tcp_position + tcp_rotation @ offset
        quaternion = quaternion_from_matrix(tcp_rotation @ _CUP_IN_TCP)
        p.resetBasePositionAndOrientation(self.object, position.tolist(), quaternion, physicsClientId=self.client)
        p.resetBaseVelocity(self.object, [0, 0, 0], [0, 0, 0], physicsClientId=self.client)
        p.changeDynamics(self.object, -1, activationState=p.ACTIVATION_STATE_WAKE_UP, physicsClientId=self.client)
        for link in range(-1, p.getNumJoints(self.robot, physicsClientId=self.client)):
            p.setCollisionFilterPair(self.robot, self.object, link, -1, 0, physicsClientId=self.client)
        for body in self.others:
            p.setCollisionFilterPair(body, self.object, -1, -1, 0, physicsClientId=self.client)
        self.constraint = p.createConstraint(
            self.robot, self.tcp_link, self.object, -1, p.JOINT_FIXED, [0, 0, 0],
            parentFramePosition=offset.tolist(), childFramePosition=[0, 0, 0],
            parentFrameOrientation=quaternion_from_matrix(_CUP_IN_TCP), physicsClientId=self.client)
        # Far above the 0.1 kg cup's weight: it must not sag or lag measurably.
        p.changeConstraint(self.constraint, maxForce=1000.0, physicsClientId=self.client)

    def release(self) -> None:
        """Remove the constraint (the next episode's reset places a new object anyway)."""
        if self.constraint >= 0:
            p.removeConstraint(self.constraint, physicsClientId=self.client)
            self.constraint = -1
