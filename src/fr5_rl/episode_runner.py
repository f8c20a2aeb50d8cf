"""The simulator node's episodes without ROS: one phase at a time, and what a command does in each.

:class:`EpisodeRunner` holds everything of a stand-in arm's run that is not a topic or a
service: the episode (:class:`~fr5_rl.episode.Episode`) and the driver in front of it, the
commands in flight, the phase, and each episode's record. The ROS node
(:mod:`fr5_rl.ros.sim_node`) feeds it commands and the clock, calls the policy node's services
when a phase asks for it, and publishes what it reports. Its phases:

======================  =====================================================  ===============
phase                   what happens                                           arm commands
======================  =====================================================  ===============
``HOLDING``             between episodes: the arm holds still                  dropped
``SETTLING``            a new scene stands; the policy is not yet told         dropped
``POSITIONING``         the policy node's reset is in flight: with             obeyed (start move)
                        ``go_to_start`` its start move, else after a teleport  or dropped
``WAITING``             the episode began; it is timed from the first command  obeyed
``RUNNING``             every control period is judged                         obeyed
``CALIBRATING``         the object is fixed in the gripper; nothing is judged  obeyed
======================  =====================================================  ===============

Gripper commands are obeyed in every phase but ``HOLDING`` and ``SETTLING``.
"""
from __future__ import annotations

import enum
import time
from collections import deque
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from .config import deep_update
from .env_config import load_env_config
from .episode import Episode, placement_record
from .scene_episodes import TableClearing
from .sim.node_params import SimNodeParams
from .sim.pacing import ArrivalQueue
from .sim.servo import DriverModel
from .tasks import EpisodeVerdict


def simulator_episode(task: str, robot: Optional[str], model_settings: Mapping[str, Any],
                      params: SimNodeParams) -> Episode:
    """The simulator's world for a model: gym's, with the objects and the arm the model was
    trained for, at the stand-in arm's own physics step (gym's control periods in lockstep).
    The simulator node and the bench that emulates the chain (``tools/bench/timing.py``) both
    build theirs here, so both place the same objects on the same seeds.

    :param task: the registered task (``reach``, ``grasp``, ``grasp_objects``, ``place``).
    :param robot: the arm (``config/robots/``); None: the configuration's.
    :param model_settings: the model's deployment overrides
        (:func:`fr5_rl.deploy.bundle.deployment_overrides`); ``{}`` without a model.
    :param params: the simulator node's parameters (``physics_dt`` s, ``solver_iterations`` at
        least, ``lockstep``).
    """
    if params.lockstep:
        return Episode.build(task, robot, model_settings)  # the gym world, as `evaluate.py` builds it
    # The node's solver iterations are a floor: a task whose contacts need more keeps its own.
    trained = load_env_config(model_settings).simulation_for(task).solver_iterations
    return Episode.build(task, robot, deep_update(dict(model_settings), {task: {"simulation": {
        "physics_dt": params.physics_dt,
        "solver_iterations": max(params.solver_iterations, trained)}}}, strict=False))


class Phase(enum.Enum):
    """Where a stand-in arm's run stands (see the module's table)."""

    HOLDING = "holding"
    SETTLING = "settling"
    POSITIONING = "positioning"
    WAITING = "waiting"
    RUNNING = "running"
    CALIBRATING = "calibrating"


class EpisodeRunner:
    """Episodes of a simulated arm behind a driver, in real time or in lockstep.

    :param sim: the simulated episode (plant, chain, task).
    :param driver: the driver's servo cycle and response between commands and joints.
    :param seed: episode k (from 0) is drawn from ``seed + k``.
    :param go_to_start: a real arm is not teleported: from the second episode on only the object
        is placed, and the policy node's start move brings the arm to its start.
    :param hold_after_episode: s the arm holds still after an episode (``~pause_between_episodes``).
    :param clock: monotonic s (injected so the phases are tested without sleeping).
    :param clearing: a clearing run (:class:`~fr5_rl.scene_episodes.TableClearing`): each episode is
        the next object of a scene of several; None: one object an episode.
    """

    def __init__(self, sim: Episode, driver: DriverModel, seed: int, go_to_start: bool, hold_after_episode: float,
                 clock: Callable[[], float] = time.monotonic, clearing: Optional[TableClearing] = None) -> None:
        self.sim, self.driver, self.seed, self.clearing = sim, driver, seed, clearing
        self.extra_records: List[Dict[str, Any]] = []  # clearing: records of the objects the last episode lost
        self.go_to_start, self.hold_after_episode, self.clock = go_to_start, hold_after_episode, clock
        self.max_width = sim.robot_spec.max_opening_width
        self.lower, self.upper = sim.robot_spec.lower_limits, sim.robot_spec.upper_limits
        self.phase = Phase.HOLDING
        self.hold_until = 0.0
        self.episode = 0  # episodes finished
        self.results: List[bool] = []  # success of each finished episode
        self.starts = 0  # policy resets asked for: only the newest one's answer ends POSITIONING
        self.arm_command: Optional[Tuple[float, ...]] = None  # the newest arm command taken (rad); None: none yet
        self.gripper_target = self.max_width
        # Real time: commands with their arrival (monotonic s), taken up by the physics step that
        # runs at that time; a loop catching up on late steps must not apply them early. The
        # gripper's too: applied at the loop's wake-up, a late loop closed the fingers ahead of
        # the arm by its lateness.
        self.arriving: ArrivalQueue = ArrivalQueue()
        self.gripper_arriving: ArrivalQueue = ArrivalQueue()
        self.tcp_path: deque = deque(maxlen=300)  # tcp positions (m, base_link), one per judged period
        self.late_periods = 0  # lockstep: periods of this episode that went without a command
        self.loop_lateness: List[float] = []  # real time: s behind the wall clock at each wake-up, this episode

    # ------------------------------------------------------------------ what the phase allows
    @property
    def holding(self) -> bool:
        """Between episodes (``HOLDING`` or ``SETTLING``): nothing is obeyed."""
        return self.phase in (Phase.HOLDING, Phase.SETTLING)

    @property
    def judged(self) -> bool:
        """Every control period is judged (``RUNNING``)."""
        return self.phase is Phase.RUNNING

    @property
    def commanded(self) -> bool:
        """The arm moves on commands that count: ``RUNNING``, or a calibration's."""
        return self.phase in (Phase.RUNNING, Phase.CALIBRATING)

    def hold_is_over(self) -> bool:
        """``HOLDING`` or ``SETTLING`` has lasted its time."""
        return self.holding and self.clock() >= self.hold_until

    @property
    def next_start_keeps_the_arm(self) -> bool:
        """The next episode places only the object (``go_to_start`` after the first episode)."""
        return self.go_to_start and self.episode > 0

    # ------------------------------------------------------------------ episodes
    def place_next(self, settle: float = 0.0, chosen_xy: Optional[Sequence[float]] = None) -> None:
        """Draw and place the next episode (seed + episodes finished): a new object, and the arm
        teleported to its start unless :attr:`next_start_keeps_the_arm`. Commands in flight are
        dropped; the driver's servo loop keeps its phase, as a real driver's runs on.

        :param settle: s the new scene stands before the policy is told (``SETTLING``); 0: at once
            (the caller then calls :meth:`begin`).
        :param chosen_xy: a clearing run: where the object the cell chose next stands (m,
            base_link; :meth:`~fr5_rl.scene_episodes.TableClearing.next_scene`); None: the rule's.
        """
        seed = self.seed + self.episode
        options: Dict[str, Any] = {}
        if self.clearing is not None:
            options["scene"] = self.clearing.next_scene(chosen_xy)
        if self.next_start_keeps_the_arm:
            options["arm_positions"] = self.sim.joint_positions().tolist()
        self.sim.start(seed, options=options or None)
        self.arm_command = None
        self.arriving.clear()
        self.gripper_arriving.clear()
        self.driver.reset(self.sim.joint_positions(), restart_cycle=False)
        self.gripper_target = self.max_width
        self.late_periods = 0
        self.loop_lateness = []
        self.tcp_path.clear()
        self.phase = Phase.SETTLING
        self.hold_until = self.clock() + settle

    def begin(self, positioning: bool) -> int:
        """The policy is told a new episode starts.

        :param positioning: its reset is in flight and ends with :meth:`positioned`
            (``POSITIONING``); False: the episode waits for its first command (``WAITING``).
        :return: this start's number, for :meth:`positioned`.
        """
        self.starts += 1
        self.phase = Phase.POSITIONING if positioning else Phase.WAITING
        self.hold_until = 0.0
        return self.starts

    def positioned(self, start: int) -> None:
        """The policy node answered the reset of ``start``: the episode is timed from its next
        command. A newer start, a calibration or an ended episode meanwhile leaves the phase."""
        if self.phase is Phase.POSITIONING and start == self.starts:
            self.phase = Phase.WAITING

    def finish(self, verdict: EpisodeVerdict, sim_time: float, lockstep: bool) -> Dict[str, Any]:
        """End the episode: its record, and ``HOLDING`` for ``hold_after_episode``.

        :param sim_time: s of simulated time at its end.
        :param lockstep: record the lockstep's late periods (else the real-time loop's lateness).
        :return: the record (episode, seed, success, failure, steps, sim_time, where the object
            started and its kind (:func:`placement_record`), and the timing).
        """
        clearing_fields: Dict[str, Any] = {}
        if self.clearing is not None:
            verdict, clearing_fields = self.clearing.finish(self.sim, verdict)
        self.episode += 1
        self.results.append(bool(verdict.success))
        record: Dict[str, Any] = {
            "episode": self.episode, "seed": self.seed + self.episode - 1, "success": bool(verdict.success),
            "failure": verdict.failure or "", "steps": verdict.steps, "sim_time": round(sim_time, 3),
            **placement_record(self.sim), **clearing_fields}
        self.extra_records = []
        for extra in (self.clearing.extra_records if self.clearing is not None else ()):
            # An object knocked over is one more object not placed: a record of its own.
            self.episode += 1
            self.results.append(False)
            self.extra_records.append({"episode": self.episode, "seed": self.seed + self.episode - 1, **extra})
        if lockstep:
            record["late_periods"] = self.late_periods
        elif self.loop_lateness:
            # A loaded machine wakes the loop late; the steps it then catches up on run with the
            # commands of their time, but the policy reads states that much older.
            late_ms = np.percentile(self.loop_lateness, [50, 99, 100]) * 1000.0
            record["loop_late_ms"] = {"p50": round(float(late_ms[0]), 1), "p99": round(float(late_ms[1]), 1),
                                      "max": round(float(late_ms[2]), 1)}
        self.phase = Phase.HOLDING
        self.hold_until = self.clock() + self.hold_after_episode
        self.arm_command = tuple(self.sim.joint_positions())
        self.arriving.clear()
        self.gripper_arriving.clear()
        return record

    def hold(self) -> None:
        """``HOLDING`` until an episode is placed again (lockstep's warm-up: commands counted, not obeyed)."""
        self.phase = Phase.HOLDING
        self.hold_until = float("inf")

    def calibrate(self, on: bool, object_in_tcp: Sequence[float]) -> bool:
        """A calibration session (``CALIBRATING``): the object fixed in the closed gripper at
        ``object_in_tcp`` (m, tcp frame), arm commands obeyed, nothing judged. Off: the object is
        let go and the caller starts the next episode.

        :return: the phase changed.
        """
        if on and self.phase is not Phase.CALIBRATING:
            self.sim.hold_object(object_in_tcp)
            self.arriving.clear()
            self.gripper_arriving.clear()
            self.phase = Phase.CALIBRATING
            self.arm_command = tuple(self.sim.joint_positions())
            self.gripper_target = float(self.sim.scene().object_size[0])  # closed on the cup
            return True
        if not on and self.phase is Phase.CALIBRATING:
            self.sim.release_object()
            self.phase = Phase.HOLDING
            return True
        return False

    # ------------------------------------------------------------------ commands
    def take_arm_command(self, positions: Sequence[float], arrived: Optional[float]) -> bool:
        """An arm command (6 finite rad, inside the limits): obeyed unless the phase drops it.

        :param arrived: monotonic s it arrived (real time: the physics step running then takes
            it up); None: lockstep, it stands from the next period.
        :return: it was obeyed.
        """
        teleported = self.phase is Phase.POSITIONING and not self.go_to_start
        if self.holding or teleported:
            return False
        if self.phase is Phase.WAITING:
            self.phase = Phase.RUNNING
        command = tuple(float(value) for value in positions)
        if arrived is None:
            self.arm_command = command
        else:
            self.arriving.push(arrived, command)
        return True

    def take_gripper_command(self, width: float, arrived: Optional[float]) -> bool:
        """A gripper command (m, clipped to the stroke): obeyed unless holding.

        :param arrived: as for :meth:`take_arm_command`.
        :return: it was obeyed.
        """
        if self.holding:
            return False
        width = float(np.clip(width, 0.0, self.max_width))
        if arrived is None:
            self.gripper_target = width
        else:
            self.gripper_arriving.push(arrived, width)
        return True

    # ------------------------------------------------------------------ advancing the plant
    def physics_step(self, step_start: float) -> None:
        """Real time: one physics step with the commands that had arrived by ``step_start``
        (monotonic s), through the driver."""
        arm_command = self.arriving.due(step_start)
        if arm_command is not None:
            self.arm_command = arm_command
        gripper_target = self.gripper_arriving.due(step_start)
        if gripper_target is not None:
            self.gripper_target = gripper_target
        self.sim.advance_physics(self.driver.targets_for_step(self.arm_command), self.gripper_target)

    def control_period(self) -> None:
        """Lockstep: one control period with the standing commands, as gym's step runs it."""
        self.sim.advance_period(self.arm_command, self.gripper_target)

    def judge(self) -> EpisodeVerdict:
        """Judge the control period just run (``RUNNING``); the tcp path grows by one point."""
        verdict = self.sim.judge_period()
        self.tcp_path.append(tuple(self.sim.tcp_position()))
        return verdict
