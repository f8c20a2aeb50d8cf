"""The gripper chain of a FAIRINO cell, in one process: the bridge node's own
:class:`~fr5_rl.drivers.gripper_bridge.GripperBridge` calling the simulator's
:class:`~fr5_rl.sim.controller_emulator.ControllerEmulator` directly (the replies XML-RPC would
carry, without a socket), on a clock the caller sets.

The environment (``randomisation.gripper_bridge_emulation``) and the chain bench
(``tools/bench/timing.py``) both run it, so that a policy trains against the code that stands
between it and the fingers in the rehearsal: the bridge's scheduling of moves and read-backs,
its deadband and debounce, and the controller's 0 after a move. No ROS, no PyBullet.
"""
from __future__ import annotations

import dataclasses
import xmlrpc.client
from typing import Any, Tuple

from ..config import load_yaml, package_root, typed
from ..drivers.fr5_xmlrpc import Call, ControllerRefused, error_code_of
from ..drivers.gripper_bridge import GripperBridge, GripperReading
from ..drivers.gripper_bridge_params import GripperBridgeParams
from ..gripper import BridgeTiming
from .controller_emulator import ControllerEmulator, ControllerEmulatorSettings

#: s of the chain's clock run at each episode's start so that the opening command and its
#: transient are over and a read-back has come through (the rehearsal's pause and start move
#: take longer than this), before the read phase is drawn.
SETTLE_S = 0.5
#: s between two polls while the chain settles.
SETTLE_TICK_S = 0.004


class InProcessController:
    """The bridge's controller client, answered by a :class:`ControllerEmulator` in this process
    (the same replies as over XML-RPC, the same refusals)."""

    def __init__(self, emulator: ControllerEmulator) -> None:
        self.emulator = emulator

    def call(self, call: Call) -> Tuple[Any, ...]:
        """One request; its values after the error code.

        :raises ControllerRefused: the emulator answered with a fault or a nonzero error code.
        """
        try:
            reply = self.emulator.serve_call(call.method, call.args)
        except xmlrpc.client.Fault as fault:
            raise ControllerRefused(f"{call} raised XML-RPC fault {fault.faultCode}: {fault.faultString}") from None
        code, values = error_code_of(reply)
        if code != 0:
            raise ControllerRefused(f"{call} returned error code {code}", code)
        return values


class ChainClock:
    """The time (s) the bridge and the emulator share; the caller moves it forward."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def load_gripper_chain_settings(sim_node_config: str = "sim_node") -> Tuple[GripperBridgeParams,
                                                                            ControllerEmulatorSettings]:
    """The bridge's parameters (config/gripper_bridge.yaml) and the emulated controller's
    (``controller_emulator`` of config/<sim_node_config>.yaml), as the rehearsal runs them."""
    root = package_root() / "config"
    bridge = typed(GripperBridgeParams, load_yaml(root / "gripper_bridge.yaml"), "config/gripper_bridge.yaml")
    emulator = typed(ControllerEmulatorSettings, load_yaml(root / f"{sim_node_config}.yaml")["controller_emulator"],
                     f"config/{sim_node_config}.yaml controller_emulator")
    return bridge, emulator


class EmulatedGripperChain:
    """The gripper behind the bridge, as the rehearsal runs it, for a simulation that steps in
    control periods: the interface of :class:`fr5_rl.gripper.BridgedGripper`.

    Each call moves the chain's clock to the episode time given and lets the bridge make every
    request due by then. One chain lives through many episodes, as the bridge and the controller
    do between the rehearsal's episodes.

    :param bridge_params: the bridge node's parameters (position mode).
    :param emulator_settings: the emulated controller's; its ``position_zero_transient`` is
        replaced by each episode's draw (:meth:`reset`).
    :param max_width: the gripper's largest opening (m), = 100 %.
    """

    def __init__(self, bridge_params: GripperBridgeParams, emulator_settings: ControllerEmulatorSettings,
                 max_width: float) -> None:
        if bridge_params.mode != "position" or bridge_params.readback_rate <= 0:
            raise ValueError("the emulated gripper chain needs the bridge in position mode with a read-back "
                             f"(mode {bridge_params.mode!r}, readback_rate {bridge_params.readback_rate:g}): "
                             "a policy cannot observe the opening otherwise")
        self.max_width = max_width
        self.timing = BridgeTiming(1.0 / bridge_params.max_call_rate, 1.0 / bridge_params.readback_rate,
                                   int(bridge_params.deadband_percent), float(bridge_params.zero_debounce),
                                   float(bridge_params.readback_max_age), float(bridge_params.readback_retry))
        self.clock = ChainClock()
        self._settings = emulator_settings
        self.emulator = ControllerEmulator(emulator_settings, 0, self.clock)  # never started: no socket
        self.bridge = GripperBridge(bridge_params, max_width, report=lambda level, text: None,
                                    client=InProcessController(self.emulator), clock=self.clock,
                                    on_reading=self._on_reading)
        self.read_width = max_width
        self._episode_start = 0.0  # the chain's clock at the episode's start
        # The bridge's start-up (reset, activation, their settle times), as at launch.
        self.emulator.set_measured_width(max_width, moving=False)
        self.bridge.submit(max_width)
        self._run(10.0, until_ready=True)
        if not self._ready():
            raise RuntimeError("the emulated gripper chain did not activate and open within 10 s of its clock")

    @classmethod
    def from_config(cls, max_width: float, sim_node_config: str = "sim_node") -> "EmulatedGripperChain":
        """The chain with the package's bridge and controller settings."""
        bridge, emulator = load_gripper_chain_settings(sim_node_config)
        return cls(bridge, emulator, max_width)

    # ------------------------------------------------------------------ the BridgedGripper interface
    def reset(self, width: float, call_phase: float, read_phase: float, zero_transient: float = 0.0) -> None:
        """A new episode with the fingers at ``width`` (m): the opening is commanded, the chain
        runs until it is read back, then on for ``read_phase`` (s), which places the episode's
        start at a random point of the read-back's cycle.

        :param call_phase: unused: after the settle no move is pending, so the first command
            goes out at once, as in the rehearsal (kept for :class:`BridgedGripper`'s interface).
        :param read_phase: s run after the settle (0 … the read period).
        :param zero_transient: s the controller reads 0 after each move in this episode.
        """
        del call_phase
        self.emulator.settings = dataclasses.replace(self._settings, position_zero_transient=float(zero_transient))
        self.emulator.calls.clear()  # its request log would otherwise grow for the life of the env
        self.emulator.set_measured_width(width, moving=False)
        self.bridge.submit(width)
        self._run(SETTLE_S + read_phase)
        self.read_width = self.bridge.measured.width if self.bridge.measured is not None else width
        self._episode_start = self.clock.now

    def command(self, width: float, now: float) -> float:
        """The width (m) the fingers are told to take at ``now`` (s since the episode's start)
        when ``width`` is wanted: the bridge takes it, and the controller's newest target comes back."""
        self._advance(now)
        self.bridge.submit(min(self.max_width, max(0.0, width)))
        self._poll()
        commanded = self.emulator.commanded_width()
        return self.max_width if commanded is None else min(self.max_width, max(0.0, commanded))

    def observe(self, measured_width: float, now: float) -> float:
        """The opening (m) the policy sees at ``now`` (s since the episode's start): the bridge's
        newest accepted read-back of the fingers, which measure ``measured_width``."""
        self._advance(now)
        self.emulator.set_measured_width(measured_width, moving=False)
        self._poll()
        return self.read_width

    # ------------------------------------------------------------------ internals
    def _on_reading(self, reading: GripperReading) -> None:
        self.read_width = reading.width

    def _advance(self, now: float) -> None:
        # Never backwards: an observation sampled early in a period follows that period's command.
        self.clock.now = max(self.clock.now, self._episode_start + now)

    def _poll(self) -> None:
        for _ in range(10):  # every request due by now (a move and a read may both be)
            if self.bridge.poll() is None:
                return

    def _ready(self) -> bool:
        """Activated, the opening sent after the activation's settle, and read back since."""
        bridge = self.bridge
        return (bridge.activated and bridge.sent is not None and bridge.measured is not None
                and bridge.last_move_at is not None and bridge.measured.stamp > bridge.last_move_at)

    def _run(self, seconds: float, until_ready: bool = False) -> None:
        end = self.clock.now + seconds
        while self.clock.now < end - 1e-12:
            self.clock.now = min(end, self.clock.now + SETTLE_TICK_S)
            self._poll()
            if until_ready and self._ready():
                return
