"""The simulated driver's servo cycle (FAIRINO: 125 Hz, one cycle of delay), without PyBullet."""
import pytest

from fr5_rl.sim.servo import ServoCycle

HOME = (0.0,) * 6
A, B = (0.1,) * 6, (0.2,) * 6


def run(servo, commands):
    """Targets of each physics step; ``commands[k]`` is the newest command before step k."""
    return [servo.targets_for_step(command) for command in commands]


def test_without_a_cycle_a_command_acts_from_the_next_step():
    assert run(ServoCycle(0, 3, HOME), [None, A, A, B]) == [HOME, A, A, B]


def test_a_command_waits_for_the_cycle_boundary_then_one_cycle():
    # 2 physics steps per cycle, 1 cycle of delay: A arrives before step 1 (mid-cycle), is
    # latched at step 2 (the next boundary) and acts from step 4 (one cycle later).
    targets = run(ServoCycle(2, 1, HOME), [None, A, A, A, A, A])
    assert targets == [HOME, HOME, HOME, HOME, A, A]


def test_only_the_newest_command_at_a_boundary_is_latched():
    # B replaces A before the boundary at step 2: A never acts.
    targets = run(ServoCycle(2, 1, HOME), [None, A, B, B, B, B])
    assert A not in targets and targets[4:] == [B, B]


def test_no_delay_latches_at_the_boundary():
    assert run(ServoCycle(2, 0, HOME), [None, A, A, A]) == [HOME, HOME, A, A]


def test_reset_drops_commands_in_flight():
    servo = ServoCycle(2, 1, HOME)
    run(servo, [A, A, A])
    servo.reset(B)
    assert run(servo, [None, None, None, None]) == [B] * 4


def test_negative_settings_are_refused():
    with pytest.raises(ValueError):
        ServoCycle(-1, 0, HOME)
