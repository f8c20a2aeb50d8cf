"""The simulator node's two loops, each a class of its own: :class:`RealTimeLoop` (the arm
locked to the wall clock, as a driver runs) and :class:`LockstepLoop` (one control period per
command, on ``/clock``). Both drive a :class:`~fr5_rl.ros.sim_node.SimulatorNode`: its world,
its publishers and its episode state, which they share with its callbacks under ``node.lock``.
"""
from __future__ import annotations

import time
from typing import Any, Optional

import rospy
from rosgraph_msgs.msg import Clock

from ..config import whole_multiple
from ..episode_runner import Phase
from ..tasks import EpisodeVerdict
from ..sim.pacing import AlignedStepSchedule, StepSchedule, TimeSchedule, WallClockPacer


class RealTimeLoop:
    """Steps physics at ``physics_dt`` against the wall clock, publishes at ``publish_rate``,
    judges every control period after an episode's first command."""

    def __init__(self, node: Any) -> None:
        """:param node: the :class:`~fr5_rl.ros.sim_node.SimulatorNode` (not imported: it imports this)."""
        self.node = node
        self.uncommanded_since: Optional[float] = None  # monotonic s the episode has waited for a command

    def run(self) -> None:
        """Simulated time is kept locked to the wall clock, as a real arm's would be
        (:class:`~fr5_rl.sim.pacing.WallClockPacer`): when the loop wakes late (a loaded machine),
        the missed physics steps are run before publishing, so a command always acts for as long
        in simulation as it did in reality. Every ``control_dt`` of simulated time after the
        first command, the environment judges the episode."""
        node = self.node
        params, sim, runner = node.params, node.sim, node.runner
        rate = rospy.Rate(1.0 / node.physics_dt)
        pacer = WallClockPacer(node.physics_dt, max_catch_up=10 * node.steps_per_publish)
        ros_minus_monotonic = rospy.Time.now().to_sec() - time.monotonic()
        judge = StepSchedule(whole_multiple(sim.control_dt, node.physics_dt) or 1)
        publish = AlignedStepSchedule(node.steps_per_publish)
        camera, markers = TimeSchedule(1.0 / params.camera_rate), TimeSchedule(1.0 / params.marker_rate)
        while not rospy.is_shutdown():
            with node.lock:
                if runner.hold_is_over():
                    if runner.phase is Phase.SETTLING:
                        node.begin_episode()
                    elif 0 < params.episodes <= runner.episode:
                        break
                    else:
                        node.start_episode(settle=params.reset_settle_time)
                if node.controller is not None:
                    node.take_controller_command()
                self._end_if_never_commanded(pacer.sim_time)
                if not runner.holding:
                    runner.loop_lateness.append(pacer.lateness())
                for step in pacer.due_steps():
                    runner.physics_step(pacer.wall_time - node.physics_dt)
                    if not runner.commanded:
                        judge.restart(step)  # episodes are timed from the first command
                    elif runner.judged and judge.due(step):
                        verdict = runner.judge()
                        if verdict.ended:
                            node.finish_episode(verdict, pacer.sim_time)
                if node.controller is not None:
                    node.report_to_controller()
                if publish.due(pacer.step):
                    # Stamped when the state was true (a driver stamps its read), not when a
                    # late loop got to publish it: replays and velocity estimates need the former.
                    stamp = rospy.Time.from_sec(pacer.wall_time + ros_minus_monotonic)
                    node.publish_state(stamp)
                    if node.target_pub is not None and camera.due(pacer.sim_time):
                        node.target_pub.publish(node.camera_message(stamp))
                    if markers.due(pacer.sim_time):
                        node.publish_markers(stamp)
            try:
                rate.sleep()
            except rospy.ROSInterruptException:
                break

    def _end_if_never_commanded(self, sim_time: float) -> None:
        """Real time (lock held): an episode that a connected policy node never commands (it holds:
        a target it refuses, a fault) ends after ``~first_command_timeout`` as failure
        ``"no_command"``, so a run always finishes; its hold message says why."""
        node = self.node
        waiting = (node.params.first_command_timeout > 0.0 and node.runner.phase is Phase.WAITING
                   and node.command_sub.get_num_connections() > 0)
        if not waiting:
            self.uncommanded_since = None
            return
        now = time.monotonic()
        if self.uncommanded_since is None:
            self.uncommanded_since = now
        elif now - self.uncommanded_since > node.params.first_command_timeout:
            self.uncommanded_since = None
            rospy.logwarn(f"sim_node: the policy node sent no command for {node.params.first_command_timeout:.0f} s "
                          "of this episode (its hold message says why): ending it as failure no_command")
            node.finish_episode(EpisodeVerdict(False, "no_command", True, False, 0, None), sim_time)


class LockstepLoop:
    """Advances one control period per command, publishing ``/clock`` (every node on
    ``/use_sim_time``), as gym's ``step`` does."""

    def __init__(self, node: Any) -> None:
        """:param node: the :class:`~fr5_rl.ros.sim_node.SimulatorNode`."""
        self.node = node

    def run(self) -> None:
        """One control period per command: publish the inputs stamped ``t``, then ``/clock`` =
        ``t``; wait for the command (the policy node's timer fires on the clock); advance one
        period as gym's ``step`` does; judge. Before an episode's first command the world waits
        (time passes, physics does not), as a gym episode starts with its first action."""
        node = self.node
        params, sim, runner = node.params, node.sim, node.runner
        period_ns = int(round(sim.control_dt * 1e9))  # integer time: 0.02 s steps stay exact
        marker_period_ns = int(round(1e9 / params.marker_rate))
        now_ns, next_marker_ns = 1_000_000_000, 0  # start at 1 s: time 0 means "no clock yet" to many nodes
        node.clock_pub.publish(Clock(clock=rospy.Time(0, now_ns)))
        self._wait_for_policy()
        now_ns = self._warm_up(now_ns, period_ns)
        with node.lock:
            node.start_episode()
        wall_start, periods = time.monotonic(), 0
        while not rospy.is_shutdown():
            with node.lock:
                if now_ns >= next_marker_ns:
                    next_marker_ns = now_ns + marker_period_ns
                    node.publish_markers(rospy.Time(0, now_ns))
                self._open_period(now_ns)
                arrived = node.command_arrived.wait_for(self._period_commanded,
                                                        timeout=params.lockstep_command_timeout)
                if runner.judged:
                    if not arrived:
                        runner.late_periods += 1
                    runner.control_period()
                    periods += 1
                    verdict = runner.judge()
                    if verdict.ended:
                        node.finish_episode(verdict, (now_ns + period_ns) * 1e-9)
                        if 0 < params.episodes <= runner.episode:
                            break
                        node.start_episode()
            now_ns += period_ns
        wall = time.monotonic() - wall_start
        if periods:
            print(f"lockstep: {periods * sim.control_dt:.1f} s simulated in {wall:.1f} s of wall time "
                  f"({periods * sim.control_dt / max(wall, 1e-9):.1f}x real time)", flush=True)

    def _warm_up(self, now_ns: int, period_ns: int) -> int:
        """Run periods without physics until one command arrives within its period: every
        connection the loop uses then stands, so the first episode loses no message. The world
        only waits (commands are ignored), so the reset that follows leaves it as gym's does.

        :return: the time (ns) after the warm-up.
        """
        node = self.node
        with node.lock:
            node.start_episode()
            node.runner.hold()  # commands are counted, not obeyed
        arrived = False
        while not arrived and not rospy.is_shutdown():
            with node.lock:
                self._open_period(now_ns)
                arrived = node.command_arrived.wait_for(self._period_commanded,
                                                        timeout=node.params.lockstep_command_timeout)
            now_ns += period_ns
        return now_ns

    def _open_period(self, now_ns: int) -> None:
        """Lockstep (lock held): the inputs stamped ``now_ns``, then ``/clock`` = ``now_ns``,
        which starts the policy node's period; its commands count from here on."""
        node = self.node
        stamp = rospy.Time(0, now_ns)
        node.publish_state(stamp)
        if node.target_pub is not None:
            node.target_pub.publish(node.camera_message(stamp))
        node.new_command = node.new_gripper_command = False
        node.clock_pub.publish(Clock(clock=stamp))

    def _period_commanded(self) -> bool:
        """Lockstep: this period's arm command (and gripper command) arrived, or shutdown."""
        node = self.node
        return (node.new_command and (node.new_gripper_command or not node.params.lockstep_gripper)) \
            or rospy.is_shutdown()

    def _wait_for_policy(self) -> None:
        """Lockstep starts once the policy node can be reset and its commands reach us, so no
        period is lost to connections still being made."""
        node = self.node
        deadline = time.monotonic() + 120.0
        if node.reset_policy is not None:
            try:
                rospy.wait_for_service(node.params.policy_reset_service, timeout=120.0)
            except rospy.ROSException:
                rospy.logwarn(f"sim_node: {node.params.policy_reset_service} not offered after 120 s; starting anyway")
        while node.command_sub.get_num_connections() == 0 and time.monotonic() < deadline \
                and not rospy.is_shutdown():
            time.sleep(0.05)
