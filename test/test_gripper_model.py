"""fr5_rl.gripper: the gripper as the bridge serves it, shared by the bridge and the environment
(randomisation.gripper_bridge_share). The model must agree with the bridge itself: the same
deadband and percent functions, the rates of config/gripper_bridge.yaml."""
import numpy as np
import pytest

from fr5_rl.config import ConfigError, load_robot_spec, load_yaml
from fr5_rl.envs import FR5Env
from fr5_rl.gripper import BridgedGripper, BridgeTiming, load_bridge_timing, percent_to_width, width_to_percent
from gripper_helpers import close_reading_back

MAX_WIDTH = load_robot_spec().max_opening_width
TIMING = BridgeTiming(call_period=0.1, read_period=0.1, deadband_percent=2, zero_debounce=0.3)


def test_the_timing_comes_from_the_bridges_parameter_file():
    params = load_yaml("gripper_bridge")
    timing = load_bridge_timing()
    assert timing.call_period == pytest.approx(1.0 / params["max_call_rate"])
    assert timing.read_period == pytest.approx(1.0 / params["readback_rate"])
    assert timing.deadband_percent == params["deadband_percent"]
    assert timing.zero_debounce == params["zero_debounce"]


def test_a_readback_rate_of_zero_is_refused(tmp_path, monkeypatch):
    import fr5_rl.gripper as gripper

    monkeypatch.setattr(gripper, "load_yaml", lambda name: {"max_call_rate": 10.0, "readback_rate": 0.0,
                                                             "deadband_percent": 2, "zero_debounce": 0.3})
    with pytest.raises(ConfigError, match="readback_rate"):
        gripper.load_bridge_timing()


def test_commands_go_out_at_the_call_rate_in_whole_percent_past_the_deadband():
    link = BridgedGripper(TIMING, MAX_WIDTH)
    link.reset(MAX_WIDTH, call_phase=0.05, read_phase=0.0)
    assert link.command(0.0, 0.0) == pytest.approx(MAX_WIDTH)  # too early: the open command stands
    assert link.command(0.0, 0.06) == 0.0  # the first call slot: closed (an end stop is always sent)
    assert link.command(0.03, 0.08) == 0.0  # next slot only at 0.16 s
    sent = link.command(0.0301, 0.16)
    assert sent == pytest.approx(percent_to_width(width_to_percent(0.0301, MAX_WIDTH), MAX_WIDTH))
    assert 100 * sent / MAX_WIDTH == pytest.approx(round(100 * sent / MAX_WIDTH))
    # 1 % away: inside the deadband, nothing new is sent however long one waits.
    assert link.command(sent + 0.01 * MAX_WIDTH, 1.0) == pytest.approx(sent)


def test_a_read_in_the_controllers_zero_transient_after_a_move_is_lost():
    """The controller reads 0 % for a moment after MoveGripper; the bridge drops that reading
    (fr5_rl.drivers.gripper_decisions.transient_zero), so the policy keeps the older one."""
    link = BridgedGripper(TIMING, MAX_WIDTH)
    link.reset(MAX_WIDTH, call_phase=0.0, read_phase=0.05, zero_transient=0.1)
    link.command(0.0, 0.0)  # a move at t = 0
    assert link.observe(0.07, 0.06) == pytest.approx(MAX_WIDTH)  # read at 0.05: inside the transient, lost
    assert link.observe(0.05, 0.16) == pytest.approx(0.05, abs=0.0051 * MAX_WIDTH)  # read at 0.15: through
    link.command(0.0101, 0.2)  # another move ...
    assert link.observe(0.03, 0.26) == pytest.approx(0.05, abs=0.0051 * MAX_WIDTH)  # ... the read at 0.25 is lost
    # A transient longer than the bridge's debounce would be passed on as a real 0: capped.
    link.reset(MAX_WIDTH, 0.0, 0.0, zero_transient=5.0)
    assert link.zero_transient == TIMING.zero_debounce


def test_the_opening_is_read_back_at_the_read_rate_and_held():
    link = BridgedGripper(TIMING, MAX_WIDTH)
    link.reset(MAX_WIDTH, call_phase=0.0, read_phase=0.03)
    assert link.observe(0.05, 0.02) == pytest.approx(MAX_WIDTH)  # no read yet: the last one holds
    first = link.observe(0.05012, 0.04)
    assert first == pytest.approx(percent_to_width(width_to_percent(0.05012, MAX_WIDTH), MAX_WIDTH))
    assert link.observe(0.01, 0.12) == pytest.approx(first)  # next read at 0.13 s
    assert link.observe(0.01, 0.13) == pytest.approx(0.01, abs=0.0051 * MAX_WIDTH)  # half a percent at most
    # A long gap (a paused simulation) reads once and keeps the phase.
    link.observe(0.02, 1.0)
    assert link.next_read == pytest.approx(1.03)


PERTURBED = {"enabled": True, "plain_episode_share": 0.0}


def test_the_environment_observes_the_read_back_in_bridge_episodes():
    env = FR5Env(task="grasp", config={"randomisation": {**PERTURBED, "gripper_bridge_share": 1.0}})
    try:
        env.reset(seed=5)
        seen, measured = close_reading_back(env, 20)
        # Whole percent, changing at most every 5 steps (10 Hz against 50 Hz), lagging the fingers.
        assert all(100 * w / MAX_WIDTH == pytest.approx(round(100 * w / MAX_WIDTH)) for w in seen)
        changes = [k for k in range(1, len(seen)) if seen[k] != seen[k - 1]]
        assert changes and all(b - a >= 5 for a, b in zip(changes, changes[1:]))
        assert np.mean(np.asarray(seen) - np.asarray(measured)) > 0.002  # closing: the read-back is wider
    finally:
        env.close()


def test_without_the_share_episodes_are_unchanged():
    """gripper_bridge_share 0 draws nothing: every other configuration keeps its episodes."""
    observations = []
    for config in ({"randomisation": PERTURBED}, {"randomisation": {**PERTURBED, "gripper_bridge_share": 0.0}}):
        env = FR5Env(task="grasp", config=config)
        obs, _ = env.reset(seed=11)
        observations.append(obs)
        env.close()
    assert np.array_equal(*observations)


def test_a_share_outside_zero_to_one_is_refused():
    with pytest.raises(ConfigError, match="gripper_bridge_share"):
        FR5Env(task="grasp", config={"randomisation": {**PERTURBED, "gripper_bridge_share": 1.5}})


# ----------------------------------------------------------------------------- the camera's target
def test_the_target_arrives_a_latency_after_each_frame_and_stands_until_the_next():
    from fr5_rl.observation import DelayedTarget

    target = DelayedTarget(latency=0.1, frame_period=1.0 / 15.0, phase=0.01)
    seen = {}
    for k in range(30):
        now = 0.02 * k
        seen[k] = target.observe((now, 0.0, 0.0), now, in_hand=False)[0]  # x = the time it was true
    # Before the first frame is through: the scene at the start.
    assert seen[5] == 0.0
    for k in range(6, 30):
        now = 0.02 * k
        capture = 0.01 + ((now - 0.1 - 0.01) // (1.0 / 15.0)) * (1.0 / 15.0)
        # The last period sampled at or before that capture: up to one period (20 ms) before it.
        assert capture - 0.02 - 1e-9 <= seen[k] <= capture + 1e-9, (k, seen[k], capture)
        assert now - seen[k] >= 0.1 - 1e-9
    assert len(set(seen.values())) < 15  # held between frames


def test_a_target_in_the_hand_is_seen_at_once():
    from fr5_rl.observation import DelayedTarget

    target = DelayedTarget(latency=0.15, frame_period=0.1, phase=0.0)
    for k in range(20):
        target.observe((0.02 * k, 0.0, 0.0), 0.02 * k, in_hand=False)
    assert target.observe((9.0, 0.0, 0.0), 0.4, in_hand=True)[0] == 9.0


def test_the_environment_sees_the_object_late_in_camera_episodes():
    env = FR5Env(task="grasp", config={"randomisation": {**PERTURBED, "target_share": 1.0,
                                                          "target_latency_s": [0.15, 0.15]}})
    try:
        env.reset(seed=2)
        target = env.episode.chain.target
        assert target is not None and target.latency == pytest.approx(0.15)
        seen = []
        observe = target.observe

        def spy(position, now, in_hand, hidden=False, *hand):
            result = observe(position, now, in_hand, hidden, *hand)
            seen.append((now, result[0]))
            return result

        target.observe = spy
        start = env.object_position().copy()
        # Push the object 5 cm under the camera's nose: the policy sees it move one latency late.
        env.plant.world.place_object((start[0] + 0.05, start[1], start[2]), yaw=0.0)
        for _ in range(15):
            env.step(np.zeros(7))
        first_seen = next(now for now, x in seen if x > start[0] + 0.04)
        # Not before the latency; at most the phase, one frame and one period later.
        assert 0.15 <= first_seen <= 0.15 + 2.0 / 15.0 + 0.02 + 1e-9
    finally:
        env.close()


def test_a_frame_captured_while_the_hand_hides_the_object_shows_where_it_was_last_seen():
    """The detector's hold: captures while hidden repeat the last visible one (a push under the
    hand is not followed); once seen again the target follows the object (one latency late)."""
    from fr5_rl.observation import DelayedTarget

    target = DelayedTarget(latency=0.0, frame_period=0.02, phase=0.0)
    seen = [target.observe((0.02 * k, 0.0, 0.0), 0.02 * k, in_hand=False, hidden=10 <= k < 20)[0]
            for k in range(30)]
    assert seen[:10] == pytest.approx([0.02 * k for k in range(10)])
    assert seen[10:20] == pytest.approx([0.18] * 10)  # the capture at k = 9, the last one visible
    assert seen[20:] == pytest.approx([0.02 * k for k in range(20, 30)])
    # Hidden from the first capture on: nothing was seen yet, so the hidden frame is all there is.
    first = DelayedTarget(latency=0.0, frame_period=0.02, phase=0.0)
    assert first.observe((1.0, 0.0, 0.0), 0.0, in_hand=False, hidden=True)[0] == 1.0
    assert first.observe((2.0, 0.0, 0.0), 0.02, in_hand=False, hidden=True)[0] == 1.0
    # Out of the hand under it (let go, or a slip): standing on the table below where the hand
    # had it, as the tracker puts it (ObjectTracker._follow_hand), not where it stood before, nor
    # in the air where the hand let go.
    slip = DelayedTarget(latency=0.0, frame_period=0.02, phase=0.0)
    slip.observe((1.0, 0.0, 0.05), 0.0, in_hand=False)
    assert slip.observe((1.2, 0.0, 0.3), 0.02, in_hand=True, hidden=True)[:3] == (1.2, 0.0, 0.3)
    assert slip.observe((1.5, 0.0, 0.05), 0.04, in_hand=False, hidden=True)[:3] == pytest.approx((1.2, 0.0, 0.05))
    assert slip.observe((1.5, 0.0, 0.05), 0.06, in_hand=False, hidden=True)[:3] == pytest.approx((1.2, 0.0, 0.05))


def test_an_object_hidden_longer_than_the_trackers_timeout_is_no_longer_published():
    """hidden_timeout: as the detector's tracker drops a track hidden for longer than its
    hidden_timeout, the target's capture time (seen_at) stops advancing (the policy node then
    finds it stale), and advances again from the first frame that shows the object; the object
    in the hand counts as a sighting. Without it, every hidden frame is published."""
    from fr5_rl.observation import DelayedTarget, tracker_hidden_timeout

    assert tracker_hidden_timeout() == pytest.approx(2.0)  # config/detector.yaml's
    for timeout in (None, 1.0):
        target = DelayedTarget(latency=0.0, frame_period=0.1, phase=0.0, hidden_timeout=timeout)
        stamps = []
        for k in range(40):  # seen until 0.5 s, hidden until 2.5 s, then seen again
            target.observe((0.3, 0.0, 0.0), 0.1 * k, in_hand=False, hidden=5 <= k < 25)
            stamps.append(target.seen_at)
        if timeout is None:
            assert stamps == pytest.approx([0.1 * k for k in range(40)])
        else:
            assert stamps[:15] == pytest.approx([0.1 * k for k in range(15)])  # 1.0 s after the sighting at 0.4 s
            assert stamps[15:25] == pytest.approx([1.4] * 10)  # dropped: nothing new
            assert stamps[25:] == pytest.approx([0.1 * k for k in range(25, 40)])
    held = DelayedTarget(latency=0.0, frame_period=0.1, phase=0.0, hidden_timeout=1.0)
    held.observe((0.3, 0.0, 0.0), 0.0, in_hand=False)
    held.observe((0.3, 0.0, 0.1), 0.8, in_hand=True, hidden=True)
    held.observe((0.3, 0.0, 0.0), 1.5, in_hand=False, hidden=True)  # let go under the hand at 0.8 s
    assert held.seen_at == pytest.approx(1.5)
    held.observe((0.3, 0.0, 0.0), 1.9, in_hand=False, hidden=True)
    assert held.seen_at == pytest.approx(1.5)


def test_a_held_object_is_seen_where_the_tracker_puts_it():
    """randomisation.target_in_hand_from_grasp: held, the object is fixed in the tcp frame as it
    was last seen relative to the lowest tcp pose with the fingers around it, centred between the
    fingers (the tracker's _take_into_hand): a grip that slid is seen where the tracker has it,
    not where it is; its yaw stays the true one. Without it the truth, as before."""
    from fr5_rl.observation import DelayedTarget

    down = np.diag([1.0, -1.0, -1.0])  # the tcp pointing down, its y axis (the fingers' closing) along -y
    for from_grasp in (True, False):
        target = DelayedTarget(latency=0.0, frame_period=0.02, phase=0.0, hand_from_grasp=from_grasp)
        standing = (0.5, 0.1, 0.03, 0.7)
        target.observe(standing, 0.0, in_hand=False)
        # The hand comes down around it (hidden), 1 cm off along the closing axis, lowest at 5 cm.
        for k, z in enumerate((0.07, 0.05, 0.06)):
            target.observe(standing, 0.02 * (k + 1), in_hand=False, hidden=True,
                           tcp=(np.array([0.5, 0.11, z]), down), around=True)
        # Lifted, the object slid 5 mm down the pads and turned 0.1 rad.
        truth = (0.5, 0.11, 0.075, 0.8)
        seen = target.observe(truth, 0.08, in_hand=True, tcp=(np.array([0.5, 0.11, 0.1]), down), around=True)
        if from_grasp:
            # 2 cm below the lowest tcp, centred between the fingers: 2 cm below the tcp now.
            assert seen == pytest.approx((0.5, 0.11, 0.08, 0.8))
        else:
            assert seen == pytest.approx(truth)
    # The grasp pose is forgotten once the fingers are no longer around the object.
    target = DelayedTarget(latency=0.0, frame_period=0.02, phase=0.0, hand_from_grasp=True)
    target.observe(standing, 0.0, in_hand=False)
    target.observe(standing, 0.02, in_hand=False, tcp=(np.array([0.5, 0.1, 0.02]), down), around=True)
    target.observe(standing, 0.04, in_hand=False, around=False)
    seen = target.observe(standing, 0.06, in_hand=True, tcp=(np.array([0.5, 0.1, 0.06]), down), around=True)
    assert seen[2] == pytest.approx(0.03)  # from the tcp of the take (3 cm above it), not the 2 cm one
    # Carried and set down, the fingers still around it: it follows the tcp until they open...
    assert target.observe(standing, 0.08, in_hand=False, hidden=True, tcp=(np.array([0.7, 0.1, 0.06]), down),
                          around=True)[:3] == pytest.approx((0.7, 0.1, 0.03))
    # ...then stays where the hand left it, and a second grasp has its own lowest pose.
    assert target.observe(standing, 0.10, in_hand=False, hidden=True)[:3] == pytest.approx((0.7, 0.1, 0.03))
    target.observe(standing, 0.12, in_hand=False, hidden=True, tcp=(np.array([0.7, 0.1, 0.055]), down), around=True)
    again = target.observe(standing, 0.14, in_hand=True, tcp=(np.array([0.7, 0.1, 0.08]), down), around=True)
    assert again[:3] == pytest.approx((0.7, 0.1, 0.055))


def test_the_camera_target_says_when_what_it_returned_was_captured():
    from fr5_rl.observation import DelayedTarget

    period, phase, latency = 1.0 / 15.0, 0.01, 0.1
    target = DelayedTarget(latency=latency, frame_period=period, phase=phase)
    for k in range(40):
        now = 0.02 * k
        target.observe((now, 0.0, 0.0), now, in_hand=False)
        if now - latency < phase:
            assert target.seen_at == 0.0  # the scene at the episode's start
        else:
            expected = phase + ((now - latency - phase + 1e-9) // period) * period
            assert target.seen_at == pytest.approx(expected)
            assert now - latency - period < target.seen_at <= now - latency + 1e-9
    target.observe((9.0, 0.0, 0.0), 0.9, in_hand=True)
    assert target.seen_at == 0.9


def test_the_environment_holds_the_target_while_the_tcp_is_within_the_hidden_radius():
    """randomisation.target_hidden_radius: with the tcp farther than the radius the camera episode
    follows a pushed object; within it, it keeps the position the object had when last seen."""
    camera = {**PERTURBED, "target_share": 1.0, "target_latency_s": [0.0, 0.0], "target_rate_hz": 50.0}
    moved = {}
    for radius in (0.0, 10.0):  # 10 m: the tcp is always "near"
        env = FR5Env(task="grasp", config={"randomisation": {**camera, "target_hidden_radius": radius}})
        try:
            obs, _ = env.reset(seed=2)
            start = env.object_position().copy()
            env.plant.world.place_object((start[0] + 0.05, start[1], start[2]), yaw=0.0)
            for _ in range(5):
                later, *_ = env.step(np.zeros(7))
            scale = env.cfg.observation.relative_position_scale
            # Object minus tcp along x (observation 20, scaled), in m: the arm holds still.
            moved[radius] = float(later[20] - obs[20]) * scale
        finally:
            env.close()
    assert moved[0.0] == pytest.approx(0.05, abs=0.005)  # followed the push
    assert moved[10.0] == pytest.approx(0.0, abs=0.005)  # held where it was last seen


def test_the_environment_holds_the_yaw_with_the_position_while_the_hand_hides_the_object():
    """The tracker holds a hidden object's last seen yaw as it holds its position (a box nudged
    under the hand was carried at the yaw it had before): turned while hidden, the observation's
    yaw block keeps the last seen one; turned in view, it follows."""
    from fr5_rl.observation import OBJECT_FEATURE_SIZE

    camera = {**PERTURBED, "target_share": 1.0, "target_latency_s": [0.0, 0.0], "target_rate_hz": 50.0}
    turned = {}
    for radius in (0.0, 10.0):  # 10 m: the tcp is always "near"
        env = FR5Env(task="grasp", config={"object": {"variety": {"enabled": True, "kinds": ["box"]}},
                                           "observation": {"object_features": True},
                                           "randomisation": {**camera, "target_hidden_radius": radius}})
        try:
            obs, _ = env.reset(seed=2)
            yaw_block = slice(len(obs) - OBJECT_FEATURE_SIZE, len(obs) - OBJECT_FEATURE_SIZE + 2)
            start = env.object_position().copy()
            env.plant.world.place_object(tuple(start), yaw=0.3)
            for _ in range(5):
                later, *_ = env.step(np.zeros(7))
            turned[radius] = float(np.abs(later[yaw_block] - obs[yaw_block]).max())
        finally:
            env.close()
    assert turned[0.0] > 0.2  # followed the turn (sin, cos of k times 0.3 rad and then some)
    assert turned[10.0] < 0.01, turned  # held at the yaw last seen


def test_the_trackers_grasp_is_judged_by_the_bridges_read_back():
    """The detector's tracker hears the fingers through the bridge's read-back (the finger joint
    states the bridge publishes), not from the fingers themselves. The environment's model of it
    judged by the true opening: behind the chain a read-back that lagged a grasp left the object
    on the table for the tracker while the environment had it in the hand (stop 65)."""
    env = FR5Env(task="grasp", config={"randomisation": {**PERTURBED, "gripper_bridge_share": 1.0,
                                                         "target_share": 1.0}})
    try:
        env.reset(seed=5)
        judged = []
        judge = env.episode.held_as_the_camera_sees
        env.episode.held_as_the_camera_sees = lambda state: judged.append(state.gripper_width) or judge(state)
        read_back, fingers = close_reading_back(env, 20)
        assert judged == pytest.approx(read_back)
        assert max(abs(np.asarray(read_back) - np.asarray(fingers))) > 0.005  # the two differed while closing
    finally:
        env.close()
