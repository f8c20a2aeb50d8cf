"""fr5_rl.sim.pacing: simulated time locked to an injected wall clock, and the schedules of the
simulator node's real-time loop (verdicts, publications, camera frames)."""
import pytest

from fr5_rl.sim.pacing import AlignedStepSchedule, ArrivalQueue, StepSchedule, TimeSchedule, WallClockPacer


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_the_pacer_runs_the_steps_the_wall_clock_says_are_due():
    clock = FakeClock()
    pacer = WallClockPacer(physics_dt=0.005, max_catch_up=10, clock=clock)
    assert list(pacer.due_steps()) == []  # no time has passed
    clock.now += 0.005
    assert list(pacer.due_steps()) == [1]  # step 0 (t = 0) was due at once: run, counted
    clock.now += 0.0124  # 17.4 ms: simulated time runs to the step within half a step of it, 15 ms
    assert list(pacer.due_steps()) == [2, 3]
    assert pacer.sim_time == pytest.approx(0.015)
    clock.now += 0.0006  # 18 ms: now 20 ms is within half a step
    assert list(pacer.due_steps()) == [4]


def test_a_late_wake_catches_up_at_most_max_catch_up_steps_a_call():
    clock = FakeClock()
    pacer = WallClockPacer(physics_dt=0.01, max_catch_up=4, clock=clock)
    clock.now += 0.1  # ten steps late
    assert len(list(pacer.due_steps())) == 4
    assert len(list(pacer.due_steps())) == 4
    assert len(list(pacer.due_steps())) == 2
    assert pacer.step == 10


def test_a_pacer_hopelessly_behind_resynchronises_instead_of_racing():
    clock = FakeClock()
    pacer = WallClockPacer(physics_dt=0.01, max_catch_up=5, max_lag=1.0, clock=clock)
    clock.now += 3.0  # the loop stalled 3 s
    assert len(list(pacer.due_steps())) == 5  # 0.05 s run, 2.95 s behind: the lag is dropped
    assert list(pacer.due_steps()) == []
    clock.now += 0.02
    assert len(list(pacer.due_steps())) == 2


def test_step_schedule_counts_from_its_restart():
    schedule = StepSchedule(4)
    schedule.restart(10)
    assert [step for step in range(11, 25) if schedule.due(step)] == [14, 18, 22]
    schedule.restart(22)
    assert not schedule.due(25) and schedule.due(26)


def test_aligned_schedule_stays_on_the_grid_after_a_late_check():
    schedule = AlignedStepSchedule(4)
    assert schedule.due(0)
    assert not schedule.due(3)
    assert schedule.due(6)  # late: due, and the next one is back on the grid at 8
    assert not schedule.due(7) and schedule.due(8)


def test_time_schedule_is_due_once_per_period_from_its_last_due_time():
    schedule = TimeSchedule(0.1)
    due = [round(k * 0.02, 2) for k in range(16) if schedule.due(k * 0.02)]
    assert due == [0.0, 0.1, 0.2, 0.3]


def test_a_late_loop_still_knows_when_each_step_was_true_on_the_wall_clock():
    # A driver stamps its read with when the state was true; a loop 30 ms late catching up must not
    # stamp the states it computes with the time it got round to them.
    clock = FakeClock()
    pacer = WallClockPacer(physics_dt=0.01, max_catch_up=10, clock=clock)
    clock.now += 0.03
    times = [pacer.wall_time for _ in pacer.due_steps()]
    assert times == pytest.approx([100.01, 100.02, 100.03])
    assert pacer.wall_time - 0.01 == pytest.approx(100.02)  # the last step began at 20 ms



def test_a_late_loop_takes_each_command_up_at_its_arrival_not_at_its_wake_up():
    # The loop wakes 40 ms late; gripper commands arrived 5 and 15 ms in, and one 35 ms in. Catching
    # up, each step runs with the newest command that had arrived when it began: applied at the
    # wake-up instead, the fingers would lead the arm by the loop's lateness.
    clock = FakeClock()
    pacer = WallClockPacer(physics_dt=0.01, max_catch_up=10, clock=clock)
    gripper = ArrivalQueue()
    for arrived, width in ((100.005, 0.06), (100.015, 0.04), (100.035, 0.0)):
        gripper.push(arrived, width)
    clock.now += 0.04
    applied, width = [], 0.08
    for _ in pacer.due_steps():
        taken = gripper.due(pacer.wall_time - pacer.physics_dt)  # the step's start
        width = width if taken is None else taken
        applied.append(width)
    assert applied == [0.08, 0.06, 0.04, 0.04]  # steps beginning at 0, 10, 20 and 30 ms
    assert len(gripper) == 1  # the 35 ms command waits for the step that begins after it
    clock.now += 0.01
    assert [gripper.due(pacer.wall_time - pacer.physics_dt) for _ in pacer.due_steps()] == [0.0]
    gripper.push(100.05, 0.08)
    gripper.clear()
    assert gripper.due(200.0) is None and len(gripper) == 0


def test_lateness_is_the_time_a_late_wake_has_to_catch_up_on():
    clock = FakeClock()
    pacer = WallClockPacer(physics_dt=0.01, max_catch_up=2, clock=clock)
    clock.now += 0.035
    assert pacer.lateness() == pytest.approx(0.035)
    list(pacer.due_steps())  # two steps at most
    assert pacer.lateness() == pytest.approx(0.015)
    list(pacer.due_steps())
    assert pacer.lateness() == pytest.approx(0.005)
