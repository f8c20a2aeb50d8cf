"""fr5_rl.sim.gripper_chain: the bridge node's GripperBridge calling the simulator's emulated
controller in-process, for the environment (randomisation.gripper_bridge_emulation) and the chain
bench. The parts are the deployed ones; these tests pin what the chain does with them: moves at
the bridge's rate in whole percent, read-backs lost in the controller's 0 after a move, a fresh
start at every episode. And the environment's motion guard (randomisation.guard_share), the
policy node's own ramp-in and joint-limit margin."""
import numpy as np
import pytest

from fr5_rl.config import ConfigError, load_robot_spec, load_yaml
from fr5_rl.envs import FR5Env
from fr5_rl.gripper import BridgedGripper, percent_to_width, width_to_percent
from fr5_rl.motion_guard import load_guard_settings
from fr5_rl.sim.gripper_chain import SETTLE_S, EmulatedGripperChain
from gripper_helpers import close_reading_back

ROBOT = load_robot_spec()
MAX_WIDTH = ROBOT.max_opening_width
PERTURBED = {"enabled": True, "plain_episode_share": 0.0}


def whole_percent(width: float) -> bool:
    return 100 * width / MAX_WIDTH == pytest.approx(round(100 * width / MAX_WIDTH))


def test_the_chain_takes_the_bridges_rates_from_its_parameter_file():
    chain = EmulatedGripperChain.from_config(MAX_WIDTH)
    params = load_yaml("gripper_bridge")
    assert chain.timing.call_period == pytest.approx(1.0 / params["max_call_rate"])
    assert chain.timing.read_period == pytest.approx(1.0 / params["readback_rate"])
    assert chain.bridge.status().activated  # started up as at launch: reset, activation, settle


def test_moves_go_out_at_the_bridges_rate_in_whole_percent():
    chain = EmulatedGripperChain.from_config(MAX_WIDTH)
    chain.reset(MAX_WIDTH, call_phase=0.0, read_phase=0.0, zero_transient=0.1)
    assert chain.command(0.03, 0.0) == pytest.approx(percent_to_width(width_to_percent(0.03, MAX_WIDTH), MAX_WIDTH))
    # Within the call period the controller keeps the first target, whatever is wanted.
    assert chain.command(0.0, 0.05) == pytest.approx(percent_to_width(width_to_percent(0.03, MAX_WIDTH), MAX_WIDTH))
    assert chain.command(0.0, 0.1) == 0.0  # the next slot: closed
    # 1 % away from what was sent: inside the deadband, nothing new goes out.
    assert chain.command(0.01 * MAX_WIDTH, 1.0) == 0.0
    moves = [call for call in chain.emulator.calls if call[1] == "MoveGripper"]
    assert len(moves) == 2 and moves[1][0] - moves[0][0] == pytest.approx(chain.timing.call_period)


def test_a_read_within_the_controllers_zero_after_a_move_is_lost():
    chain = EmulatedGripperChain.from_config(MAX_WIDTH)
    chain.reset(MAX_WIDTH, call_phase=0.0, read_phase=0.0, zero_transient=0.15)
    chain.command(0.0, 0.0)
    seen = [(t, chain.observe(MAX_WIDTH * (1.0 - t), t)) for t in np.arange(0.02, 0.42, 0.02)]
    # Until 0.15 s after the move every read-back is the controller's 0, dropped: the open width stands.
    assert all(width == pytest.approx(MAX_WIDTH) for t, width in seen if t < 0.15)
    later = [width for t, width in seen if t >= 0.3]
    assert later and all(width < MAX_WIDTH and whole_percent(width) for width in later)
    assert chain.bridge.ignored_zeros >= 1


def test_every_episode_starts_open_and_read_back_whatever_the_last_one_left():
    chain = EmulatedGripperChain.from_config(MAX_WIDTH)
    chain.reset(MAX_WIDTH, 0.0, 0.0, zero_transient=0.1)
    chain.command(0.0, 0.0)
    chain.observe(0.0, 1.0)  # the last episode ended closed
    before = chain.clock.now
    chain.reset(MAX_WIDTH, call_phase=0.0, read_phase=0.04, zero_transient=0.1)
    assert chain.clock.now == pytest.approx(before + SETTLE_S + 0.04)
    assert chain.read_width == pytest.approx(MAX_WIDTH)
    assert chain.command(MAX_WIDTH, 0.0) == pytest.approx(MAX_WIDTH)
    assert chain.emulator.settings.position_zero_transient == pytest.approx(0.1)


def test_a_bridge_without_read_back_is_refused():
    from fr5_rl.sim.gripper_chain import load_gripper_chain_settings

    bridge, emulator = load_gripper_chain_settings()
    import dataclasses

    with pytest.raises(ValueError, match="read-back"):
        EmulatedGripperChain(dataclasses.replace(bridge, readback_rate=0.0), emulator, MAX_WIDTH)


def test_the_environment_observes_the_chains_read_back_in_bridge_episodes():
    env = FR5Env(task="grasp", config={"randomisation": {**PERTURBED, "gripper_bridge_share": 1.0,
                                                         "gripper_bridge_emulation": True}})
    try:
        assert isinstance(env.episode.chain.bridge_model, EmulatedGripperChain)
        env.reset(seed=5)
        seen, measured = close_reading_back(env, 25)
        assert all(whole_percent(width) for width in seen)
        assert measured[-1] < MAX_WIDTH - 0.02  # the fingers closed ...
        assert np.mean(np.asarray(seen) - np.asarray(measured)) > 0.002  # ... and the read-back lagged them
    finally:
        env.close()


def test_the_new_keys_draw_nothing_unless_asked_for():
    """Left at their defaults, gripper_bridge_emulation and guard_share build nothing and draw
    nothing, so every other configuration keeps its episodes (tools/rollout_hash.py checks the
    shipped ones bit for bit); any guard share at all draws once per episode."""
    def trace(extra):
        env = FR5Env(task="grasp", config={"randomisation": {**PERTURBED, "gripper_bridge_share": 0.5, **extra}})
        try:
            if not extra:
                assert env.episode.chain.guard is None and isinstance(env.episode.chain.bridge_model, BridgedGripper)
            obs, _ = env.reset(seed=11)
            steps = [obs] + [env.step(action)[0] for action in np.random.default_rng(0).uniform(-1, 1, (30, 7))]
            return np.array(steps)
        finally:
            env.close()

    plain = trace({})
    assert np.array_equal(plain, trace({"gripper_bridge_emulation": False, "guard_share": 0.0}))
    # A share too small to ever pick the guard still draws: the episode's later draws move on.
    assert not np.array_equal(plain, trace({"guard_share": 1e-12}))


def test_in_guard_episodes_the_velocity_limit_ramps_in_from_the_start():
    settings = load_guard_settings()
    dt = 0.02
    for share, ramped in ((1.0, True), (0.0, False)):
        env = FR5Env(task="grasp", config={"randomisation": {**PERTURBED, "guard_share": share,
                                                             "observation_noise_std": 0.0}})
        try:
            env.reset(seed=3)
            before = env.joint_positions()
            env.step(np.ones(7))  # the largest step the action allows, on every joint
            moved = np.abs(env.joint_positions() - before)
            first_limit = ROBOT.velocity_limits * dt * (dt / settings.ramp_time)  # the ramp's first period
            if ramped:
                assert np.all(moved <= first_limit + 1e-3)
            else:
                assert np.max(moved) > 2 * np.max(first_limit)
        finally:
            env.close()


def test_a_guard_share_outside_zero_to_one_is_refused():
    with pytest.raises(ConfigError, match="guard_share"):
        FR5Env(task="grasp", config={"randomisation": {**PERTURBED, "guard_share": -0.1}})


def stream_read_back_ages(link, steps: int = 100) -> list:
    """A policy's stream of widths, each past the deadband from the last, every 20 ms, behind
    ``link`` (a chain or the environment's model of it) reset with the rehearsal's 0.1 s transient:
    the age (s) of the newest accepted read-back at each step, and the moves made."""
    link.reset(MAX_WIDTH, call_phase=0.0, read_phase=0.0, zero_transient=0.1)
    seen, sent = [], []
    for k in range(steps):
        t = 0.02 * k
        sent.append(link.command(0.04 + 0.01 * (-1) ** k, t))  # 30 and 50 mm in turn
        # Fingers that open a whole percent every step, so that a read-back tells which step it saw.
        seen.append(width_to_percent(link.observe(k * MAX_WIDTH / 100.0, t), MAX_WIDTH))
    # A read-back's age: since the step whose fingers it shows (the start's open width: none yet).
    ages = [0.02 * (k - percent) if percent <= k else 0.02 * k for k, percent in enumerate(seen)]
    moves = sum(1 for a, b in zip(sent, sent[1:]) if a != b)
    return ages, moves


def chain_with(readback_max_age: float) -> EmulatedGripperChain:
    import dataclasses

    from fr5_rl.sim.gripper_chain import load_gripper_chain_settings

    bridge, emulator = load_gripper_chain_settings()
    return EmulatedGripperChain(dataclasses.replace(bridge, readback_max_age=readback_max_age), emulator, MAX_WIDTH)


def test_a_stream_of_moves_no_longer_blinds_the_read_back():
    # Before readback_max_age, a width that moved past the deadband every call period kept every
    # read inside the controller's 0 after a move: the read-back stood still for the whole stream
    # (the rehearsal's place timeouts, stop 65). Now a move waits for a read past the transient.
    params = load_yaml("gripper_bridge")
    blind, _ = stream_read_back_ages(chain_with(0.0))
    assert max(blind) > 1.5  # the old scheduling: nothing read for the whole stream
    ages, moves = stream_read_back_ages(chain_with(params["readback_max_age"]))
    bound = params["readback_max_age"] + 0.1 + params["readback_retry"] + 0.02  # + transient + a retry + a step
    assert max(ages[10:]) <= bound, max(ages)
    assert moves >= 12  # of 20 call slots in 2 s: the stream still goes out


def test_the_environments_model_of_the_bridge_keeps_the_read_back_as_fresh_as_the_chain():
    from fr5_rl.gripper import load_bridge_timing

    model_ages, model_moves = stream_read_back_ages(BridgedGripper(load_bridge_timing(), MAX_WIDTH))
    chain_ages, chain_moves = stream_read_back_ages(EmulatedGripperChain.from_config(MAX_WIDTH))
    # The model reads on a fixed grid, the bridge a read period after its last read: the same
    # bound on the read-back's age (within a step), about as many moves.
    assert max(model_ages[10:]) == pytest.approx(max(chain_ages[10:]), abs=0.021)
    assert model_moves == pytest.approx(chain_moves, rel=0.3)


def test_moves_do_not_wait_on_a_read_back_the_controller_refuses():
    # An SDK without GetGripperCurPosition refuses every read: a stale read-back must not hold
    # the moves back for ever.
    from fr5_rl.drivers.fr5_xmlrpc import ControllerRefused

    chain = EmulatedGripperChain.from_config(MAX_WIDTH)
    chain.reset(MAX_WIDTH, call_phase=0.0, read_phase=0.0, zero_transient=0.1)
    answer = chain.bridge.client.call

    def refuse_reads(call):
        if call.method == "GetGripperCurPosition":
            raise ControllerRefused(f"{call}: no such method on this SDK")
        return answer(call)

    chain.bridge.client.call = refuse_reads
    sent = [chain.command(0.04 + 0.01 * (-1) ** k, 0.02 * k) for k in range(100)]
    moves = sum(1 for a, b in zip(sent, sent[1:]) if a != b)
    assert moves >= 18  # every call slot of 2 s
