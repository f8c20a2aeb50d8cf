"""A PyBullet world with a table and one graspable object; one instance per environment.

Every call passes ``physicsClientId`` so several worlds coexist in one process.
"""
from __future__ import annotations

import os
from typing import Optional, Sequence, Tuple

import numpy as np
from .bullet import p

from ..env_config import SimulationConfig, TableConfig


class PyBulletWorld:
    """Owns one PyBullet client: physics settings, the table, the object, stepping."""

    def __init__(self, sim_cfg: SimulationConfig, gui: bool = False, renders: bool = True) -> None:
        """``renders=False``: a world nobody takes pictures of, which is faster to build.

        PyBullet's built-in TinyRenderer converts every new body into a render mesh (0.3 ms
        for the object, at every reset); without a renderer that work is skipped and
        :meth:`render` is refused.
        """
        if gui and not os.environ.get("DISPLAY"):
            # PyBullet's GUI would kill the whole process without a display.
            raise RuntimeError("render_mode='human' needs an X display; use xvfb-run or render_mode='rgb_array'")
        self.client = p.connect(p.GUI if gui else p.DIRECT)
        if self.client < 0:
            raise RuntimeError("PyBullet could not connect (is another GUI instance open?)")
        self.object_spinning_friction = sim_cfg.object_spinning_friction
        self.physics_dt = sim_cfg.physics_dt
        self.substeps = int(round(sim_cfg.control_dt / self.physics_dt))
        p.setTimeStep(self.physics_dt, physicsClientId=self.client)
        p.setGravity(0.0, 0.0, sim_cfg.gravity, physicsClientId=self.client)
        p.setPhysicsEngineParameter(
            numSolverIterations=sim_cfg.solver_iterations,
            deterministicOverlappingPairs=1,
            physicsClientId=self.client,
        )
        if gui:
            p.configureDebugVisualizer(p.COV_ENABLE_GUI, 0, physicsClientId=self.client)
        self.renders = renders or gui
        if not self.renders:
            self._unload_renderer()
        self.table_id: Optional[int] = None
        self.object_id: Optional[int] = None
        self._object_shape: Optional[Tuple] = None
        self._object_shapes: Tuple[int, int] = (-1, -1)
        self._object_settling = False  # placed, and not yet through its first physics step

    # ------------------------------------------------------------------ scene
    def add_table(self, table_cfg: TableConfig) -> int:
        """Static box whose top face lies at ``top_height`` in base_link; returns its body id."""
        sx, sy, thickness = table_cfg.size
        half = [sx / 2.0, sy / 2.0, thickness / 2.0]
        cx, cy = table_cfg.center_xy
        top = table_cfg.top_height
        collision = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=self.client)
        visual = p.createVisualShape(
            p.GEOM_BOX, halfExtents=half, rgbaColor=[0.55, 0.42, 0.3, 1.0], physicsClientId=self.client
        )
        self.table_id = p.createMultiBody(
            0.0, collision, visual, [cx, cy, top - thickness / 2.0], physicsClientId=self.client
        )
        p.changeDynamics(
            self.table_id, -1, lateralFriction=table_cfg.lateral_friction, physicsClientId=self.client
        )
        return self.table_id

    def set_object(self, shape: str, dims: Tuple[float, ...], mass: float, friction: float) -> int:
        """Create the object as a new body (at the start of every episode); returns its id.

        ``dims`` is (radius, height) for a cylinder, (half_extent,) for a cube or (half_x, half_y,
        half_z) for a box, in metres. A new
        body carries no contact cache or sleep history from the last episode. PyBullet still
        keeps a trace of the episode before (the same seed after a different one differs by
        ~1e-8 m, in rare contact-rich cases by up to 0.4 mm); only a rebuilt world
        (resetSimulation) would erase it, at several times the cost of an episode. Runs that must
        match a serial evaluation episode by episode (``evaluate.py --ray``) replay the seed
        before their first one.
        """
        body = self._create_object(shape, dims)  # raises before anything is removed
        if self.object_id is not None:
            p.removeBody(self.object_id, physicsClientId=self.client)
        self.object_id = body
        p.changeDynamics(
            body, -1, mass=mass, lateralFriction=friction, spinningFriction=self.object_spinning_friction,
            rollingFriction=0.0001, physicsClientId=self.client,
        )
        return body

    def add_body(self, shape: str, dims: Tuple[float, ...], mass: float, friction: float,
                 color: Sequence[float] = (0.85, 0.2, 0.15, 1.0)) -> int:
        """Another object, beside :attr:`object_id` (a scene of several objects): ``dims`` as for
        :meth:`set_object`; returns its body id. Remove it with :meth:`remove_body`."""
        collision, visual = self._shapes(shape, dims, color)
        body = p.createMultiBody(mass, collision, visual, [0, 0, 1], physicsClientId=self.client)
        p.changeDynamics(body, -1, lateralFriction=friction, spinningFriction=self.object_spinning_friction,
                         rollingFriction=0.0001, physicsClientId=self.client)
        return body

    def remove_body(self, body: int) -> None:
        """Remove a body made by :meth:`add_body`."""
        p.removeBody(body, physicsClientId=self.client)

    def place_body(self, body: int, position: Sequence[float], quaternion: Sequence[float]) -> None:
        """Teleport a body made by :meth:`add_body` to ``position`` (m) and ``quaternion`` (x, y,
        z, w), at rest, asleep until something touches it (as :meth:`place_object` leaves the
        object, and for the same reason: an awake neighbour costs physics steps)."""
        p.resetBasePositionAndOrientation(body, list(position), list(quaternion), physicsClientId=self.client)
        p.resetBaseVelocity(body, [0, 0, 0], [0, 0, 0], physicsClientId=self.client)
        p.changeDynamics(body, -1, activationState=p.ACTIVATION_STATE_ENABLE_SLEEPING, physicsClientId=self.client)
        p.changeDynamics(body, -1, activationState=p.ACTIVATION_STATE_SLEEP, physicsClientId=self.client)

    def body_pose(self, body: int) -> Tuple[Tuple[float, float, float], Tuple[float, float, float, float]]:
        """A body's centre (m) and quaternion (x, y, z, w) in base_link."""
        return p.getBasePositionAndOrientation(body, physicsClientId=self.client)

    def _shapes(self, shape: str, dims: Tuple[float, ...], color: Sequence[float]) -> Tuple[int, int]:
        """A new collision shape and (rendering worlds only) visual shape for an object."""
        if shape == "cylinder":
            radius, height = dims
            collision = p.createCollisionShape(p.GEOM_CYLINDER, radius=radius, height=height,
                                               physicsClientId=self.client)
            visual = p.createVisualShape(p.GEOM_CYLINDER, radius=radius, length=height, rgbaColor=list(color),
                                         physicsClientId=self.client) if self.renders else -1
        elif shape == "box":
            halves = [dims[0]] * 3 if len(dims) == 1 else list(dims)  # a cube, or (half_x, half_y, half_z)
            collision = p.createCollisionShape(p.GEOM_BOX, halfExtents=halves, physicsClientId=self.client)
            visual = p.createVisualShape(p.GEOM_BOX, halfExtents=halves, rgbaColor=list(color),
                                         physicsClientId=self.client) if self.renders else -1
        else:
            raise ValueError(f"object.shape must be 'cylinder' or 'box', got '{shape}'")
        return collision, visual

    def _create_object(self, shape: str, dims: Tuple[float, ...]) -> int:
        key = (shape, tuple(round(d, 6) for d in dims))
        if key != self._object_shape:  # shapes are reused while the size stays the same
            self._object_shapes, self._object_shape = self._shapes(shape, dims, (0.85, 0.2, 0.15, 1.0)), key
        return p.createMultiBody(1.0, *self._object_shapes, [0, 0, 1], physicsClientId=self.client)

    def place_object(self, position: Sequence[float], yaw: float = 0.0) -> None:
        """Teleport the object to ``position`` (m, base_link) at rest, upright, with ``yaw`` (rad).

        The object then rests asleep until something touches it. In the first physics step after
        a teleport PyBullet (3.2.7) lets it drop onto the table, which wakes it however it was
        asked to sleep, so the request that holds is made right after that step (:meth:`step`,
        :meth:`step_physics`). Awake on the table, the object wobbled by up to ~0.2 mm over an
        episode and cost a quarter of every physics step (docs/experiments.md); asleep it costs
        next to nothing, and the first touch of a finger wakes it as before.
        """
        orientation = p.getQuaternionFromEuler([0.0, 0.0, yaw])
        p.resetBasePositionAndOrientation(self.object_id, position, orientation, physicsClientId=self.client)
        p.resetBaseVelocity(self.object_id, [0, 0, 0], [0, 0, 0], physicsClientId=self.client)
        # The first step settles the object as it always did: these two calls (a sleep request
        # that does not yet hold) are part of how every episode starts.
        p.changeDynamics(self.object_id, -1, activationState=p.ACTIVATION_STATE_ENABLE_SLEEPING,
                         physicsClientId=self.client)
        p.changeDynamics(self.object_id, -1, activationState=p.ACTIVATION_STATE_SLEEP,
                         physicsClientId=self.client)
        self._object_settling = True

    def wake_object(self) -> None:
        """Wake the object and cancel its pending sleep: something other than a touch is about to
        move it (a hand-over into the gripper)."""
        p.changeDynamics(self.object_id, -1, activationState=p.ACTIVATION_STATE_WAKE_UP, physicsClientId=self.client)
        self._object_settling = False

    def _sleep_settled_object(self) -> None:
        # After the first physics step since the placement: the request that holds.
        p.changeDynamics(self.object_id, -1, activationState=p.ACTIVATION_STATE_SLEEP, physicsClientId=self.client)
        self._object_settling = False

    def object_pose(self) -> Tuple[Tuple[float, float, float], Tuple[float, float, float, float]]:
        """Object centre position (m) and quaternion (x, y, z, w) in base_link."""
        return p.getBasePositionAndOrientation(self.object_id, physicsClientId=self.client)

    # ------------------------------------------------------------------ physics
    def set_physics_dt(self, physics_dt: float, control_dt: float) -> None:
        """Change the physics step (s); the number of substeps per control step follows."""
        self.physics_dt = float(physics_dt)
        self.substeps = int(round(float(control_dt) / self.physics_dt))
        p.setTimeStep(self.physics_dt, physicsClientId=self.client)

    def step(self) -> None:
        """Advance one control period (``substeps`` physics steps)."""
        client, step_simulation = self.client, p.stepSimulation
        substeps = self.substeps
        if self._object_settling:
            step_simulation(physicsClientId=client)
            self._sleep_settled_object()
            substeps -= 1
        for _ in range(substeps):
            step_simulation(physicsClientId=client)

    def step_physics(self) -> None:
        """Advance one physics step (``physics_dt`` seconds)."""
        p.stepSimulation(physicsClientId=self.client)
        if self._object_settling:
            self._sleep_settled_object()

    def save_state(self) -> Tuple[int, bool]:
        """The simulation as it stands (every body's pose and velocity, joint states, contacts)
        for :meth:`restore_state`, with the same bodies still in the world. The saved state holds
        simulator memory until :meth:`discard_state`. About 2 ms."""
        return p.saveState(physicsClientId=self.client), self._object_settling

    def restore_state(self, state: Tuple[int, bool]) -> None:
        """Go back to a state from :meth:`save_state` (about 0.06 ms); it stays saved."""
        state_id, self._object_settling = state
        p.restoreState(stateId=state_id, physicsClientId=self.client)

    def discard_state(self, state: Tuple[int, bool]) -> None:
        """Free a state from :meth:`save_state`."""
        p.removeState(state[0], physicsClientId=self.client)

    def _unload_renderer(self) -> None:
        # The TinyRenderer is linked into PyBullet as a plugin; loading it by name returns the
        # loaded instance's id. Should a PyBullet build lack it, nothing changes.
        plugin = p.loadPlugin("tinyRendererPlugin", physicsClientId=self.client)
        if plugin >= 0:
            p.unloadPlugin(plugin, physicsClientId=self.client)

    def render(self, width: int = 480, height: int = 360, target=(-0.45, 0.0, 0.15)) -> np.ndarray:
        """RGB image (H, W, 3) uint8 from a fixed camera, headless TinyRenderer."""
        if not self.renders:
            raise RuntimeError("this world was built with renders=False; build the environment with "
                               "render_mode='rgb_array' to take pictures")
        view = p.computeViewMatrixFromYawPitchRoll(
            cameraTargetPosition=target, distance=1.5, yaw=-60.0, pitch=-30.0, roll=0.0, upAxisIndex=2,
            physicsClientId=self.client,
        )
        proj = p.computeProjectionMatrixFOV(fov=50.0, aspect=width / height, nearVal=0.05, farVal=5.0,
                                            physicsClientId=self.client)
        _, _, rgba, _, _ = p.getCameraImage(
            width, height, view, proj, renderer=p.ER_TINY_RENDERER, physicsClientId=self.client
        )
        return np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4)[:, :, :3]

    def close(self) -> None:
        """Disconnect the client (safe to call twice)."""
        if self.client is not None and self.client >= 0:
            try:
                p.disconnect(physicsClientId=self.client)
            except p.error:
                pass
            self.client = -1
