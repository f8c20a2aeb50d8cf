"""A recorded run of the arm, read from a bag (``record.launch``'s), as arrays.

The arm's joint states are taken at their header stamps (when the driver measured them); the
commands, which carry no header (std_msgs/Float64MultiArray), at the time the recorder received
them: on one machine or a switched LAN that is within a millisecond of when the driver did.
Joints are matched by name, never by index.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

#: Where each series is looked for, first found wins: the vendor driver's topics, then the
#: default driver's (the simulator's driver:=default).
JOINT_STATE_TOPICS = ("/frrobot/joint_states", "/joint_states")
COMMAND_TOPICS = ("/frrobot/joints_position_controller/command", "/fr5/arm_controller/command")
GRIPPER_COMMAND_TOPIC = "/fr5/gripper/command"
#: The rehearsal's episode outcomes: after each the simulated arm ignores commands for
#: ``hold_s`` (a pause no real arm makes, left out of comparisons).
OUTCOME_TOPIC = "/fr5_sim/episode_outcome"


class RecordingError(ValueError):
    """A bag that cannot serve the tool: the message names what is missing and what to do."""


@dataclass
class RunRecording:
    """One recorded run.

    :param joint_names: the arm's joints, controller order (j1..j6).
    :param state_times: (n,) s, stamps of the joint states (ROS time), increasing.
    :param positions: (n, 6) rad, measured joint positions at ``state_times``.
    :param command_times: (m,) s, when each arm command was received.
    :param commands: (m, 6) rad, the commanded joint positions (controller order).
    :param gripper_times: (k,) s; ``gripper_widths``: (k,) m, the gripper commands.
    :param topics: which topic each series came from.
    :param source: the bag's path.
    :param pauses: (start, end) s of stretches in which the arm ignored its commands (the
        rehearsal's pause between episodes); empty for a real arm.
    """

    joint_names: List[str]
    state_times: np.ndarray
    positions: np.ndarray
    command_times: np.ndarray
    commands: np.ndarray
    gripper_times: np.ndarray
    gripper_widths: np.ndarray
    topics: Dict[str, str]
    source: str
    pauses: List[Tuple[float, float]] = field(default_factory=list)

    @property
    def duration(self) -> float:
        """s from the first joint state to the last."""
        return float(self.state_times[-1] - self.state_times[0]) if len(self.state_times) > 1 else 0.0

    def moving_time(self, speed_threshold: float = 0.05) -> float:
        """s of the run in which some joint moved faster than ``speed_threshold`` (rad/s),
        judged between consecutive joint states: the part of a run that says anything about
        how the arm follows its commands."""
        if len(self.state_times) < 2:
            return 0.0
        dt = np.diff(self.state_times)
        speed = np.abs(np.diff(self.positions, axis=0)) / np.maximum(dt, 1e-9)[:, None]
        return float(dt[(speed > speed_threshold).any(axis=1)].sum())

    def window(self, start: float, end: float) -> "RunRecording":
        """The part of the run between ``start`` and ``end`` (s, ROS time); the command
        standing at ``start`` is kept."""
        states = (self.state_times >= start) & (self.state_times <= end)
        first = max(int(np.searchsorted(self.command_times, start, side="right")) - 1, 0)
        commands = np.zeros(len(self.command_times), dtype=bool)
        commands[first:] = self.command_times[first:] <= end
        grippers = self.gripper_times <= end
        return RunRecording(self.joint_names, self.state_times[states], self.positions[states],
                            self.command_times[commands], self.commands[commands], self.gripper_times[grippers],
                            self.gripper_widths[grippers], self.topics, self.source,
                            [(a, b) for a, b in self.pauses if b >= start and a <= end])


def bag_topics(path: Path) -> Dict[str, int]:
    """Topics of a bag and their message counts.

    :raises RecordingError: the file is missing or not a readable bag.
    """
    import rosbag

    if not path.is_file():
        raise RecordingError(f"{path}: no such bag (record one with: roslaunch fr5_rl record.launch bag:={path})")
    try:
        with rosbag.Bag(str(path)) as bag:
            info = bag.get_type_and_topic_info()
    except (rosbag.ROSBagException, OSError, ValueError) as error:
        raise RecordingError(f"{path}: not a readable bag ({error}); if the recorder was killed, "
                             f"`rosbag reindex {path}.active` recovers it") from None
    return {topic: entry.message_count for topic, entry in info.topics.items()}


def pick_topic(available: Dict[str, int], given: Optional[str], candidates: Sequence[str], what: str,
               path: Path, option: str) -> str:
    """The topic to read ``what`` from: ``given``, or the first of ``candidates`` the bag holds.

    :raises RecordingError: none of them has a message (one line naming the topic).
    """
    wanted = [given] if given else list(candidates)
    for topic in wanted:
        if available.get(topic, 0) > 0:
            return topic
    raise RecordingError(f"{path}: no messages on {' or '.join(wanted)} ({what}); record it with record.launch, "
                         f"or name the topic with {option}")


def read_recording(path: Path, joint_names: Sequence[str], joint_states_topic: Optional[str] = None,
                   command_topic: Optional[str] = None) -> RunRecording:
    """Read a run from a bag.

    :param path: the bag.
    :param joint_names: the arm's joints in controller order (the commands' order).
    :param joint_states_topic: sensor_msgs/JointState topic; None: the vendor's, else the default.
    :param command_topic: std_msgs/Float64MultiArray topic; None: the vendor's, else the default.
    :raises RecordingError: a topic is missing, a joint is never named, or a command has the
        wrong length.
    """
    import rosbag

    available = bag_topics(path)
    state_topic = pick_topic(available, joint_states_topic, JOINT_STATE_TOPICS, "the arm's joint states", path,
                             "--joint-states-topic")
    arm_topic = pick_topic(available, command_topic, COMMAND_TOPICS, "the arm's commands", path, "--command-topic")
    names = list(joint_names)
    state_times: List[float] = []
    positions: List[List[float]] = []
    command_times: List[float] = []
    commands: List[List[float]] = []
    gripper_times: List[float] = []
    gripper_widths: List[float] = []
    pauses: List[Tuple[float, float]] = []
    with rosbag.Bag(str(path)) as bag:
        for topic, message, received in bag.read_messages(topics=[state_topic, arm_topic, GRIPPER_COMMAND_TOPIC,
                                                                  OUTCOME_TOPIC]):
            if topic == state_topic:
                index = {name: i for i, name in enumerate(message.name)}
                if not all(name in index for name in names):
                    continue  # e.g. the gripper's own joint states on a shared topic
                stamp = message.header.stamp.to_sec() or received.to_sec()
                state_times.append(stamp)
                positions.append([message.position[index[name]] for name in names])
            elif topic == arm_topic:
                if len(message.data) != len(names):
                    raise RecordingError(f"{path}: a command on {arm_topic} has {len(message.data)} values, "
                                         f"the arm {len(names)} joints")
                command_times.append(received.to_sec())
                commands.append(list(message.data))
            elif topic == OUTCOME_TOPIC:
                try:
                    hold = float(json.loads(message.data).get("hold_s", 0.0))
                except (ValueError, AttributeError):
                    continue
                if hold > 0.0:
                    pauses.append((received.to_sec(), received.to_sec() + hold))
            else:
                gripper_times.append(received.to_sec())
                gripper_widths.append(float(message.data))
    if not state_times:
        raise RecordingError(f"{path}: no joint state on {state_topic} names all of {', '.join(names)}")
    order = np.argsort(state_times, kind="stable")
    return RunRecording(names, np.asarray(state_times)[order], np.asarray(positions, dtype=float)[order],
                        np.asarray(command_times, dtype=float), np.asarray(commands, dtype=float).reshape(-1, len(names)),
                        np.asarray(gripper_times, dtype=float), np.asarray(gripper_widths, dtype=float),
                        {"joint_states": state_topic, "command": arm_topic}, str(path), pauses)
