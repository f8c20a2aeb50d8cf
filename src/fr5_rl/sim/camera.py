"""A simulated RGB-D camera: a render-only PyBullet world (table, FR5, object) that mirrors a
simulator's state and is photographed through a pinhole model.

Nothing here steps physics: the caller sets the joints and the object pose it read from the
simulator, then renders. The projection is built from plain intrinsics (fx, fy, cx, cy), so the
image obeys exactly the model the CameraInfo carries.
"""
from __future__ import annotations

import pkgutil
from typing import List, Mapping, Optional, Sequence, Tuple

import numpy as np
from .bullet import p

from ..env_config import EnvConfig
from .robot import urdf_for_pybullet
from .world import PyBulletWorld

RENDERERS = ("tiny", "egl")

# OpenGL's eye frame (x right, y up, looking along -z) in the optical frame (x right, y down,
# z forward): y and z flip.
_GL_IN_OPTICAL = np.diag([1.0, -1.0, -1.0, 1.0])


class SimulatedCamera:
    """The scene as a depth camera at a fixed pose sees it.

    :param env_cfg: ``config/env.yaml`` as loaded (:class:`~fr5_rl.env_config.EnvConfig`) (table and simulation sections are used).
    :param joint_names: the URDF joints the caller will set by name (arm and fingers).
    :param base_from_optical: 4x4 pose of the optical frame in base_link (m).
    :param projection: 4x4 OpenGL projection of the camera model
        (:meth:`fr5_rl.perception.camera_model.Intrinsics.opengl_projection`).
    :param width: image width (pixels).
    :param height: image height (pixels).
    :param near: near clipping distance (m).
    :param far: far clipping distance (m); nothing beyond it is measured (depth 0).
    :param renderer: ``"tiny"`` (PyBullet's CPU TinyRenderer) or ``"egl"`` (its EGL plugin,
        hardware or software OpenGL).
    """

    def __init__(self, env_cfg: EnvConfig, joint_names: Sequence[str], base_from_optical: np.ndarray,
                 projection: np.ndarray, width: int, height: int, near: float, far: float,
                 renderer: str = "tiny") -> None:
        if renderer not in RENDERERS:
            raise ValueError(f"renderer must be one of {RENDERERS}, got {renderer!r}")
        self.world = PyBulletWorld(env_cfg.simulation, gui=False, renders=True)
        client = self.client = self.world.client
        self._egl_plugin = -1
        if renderer == "egl":
            # Before any body exists: the plugin only draws what is created after it loads.
            egl = pkgutil.get_loader("eglRenderer")
            path = egl.get_filename() if egl is not None else "eglRendererPlugin"
            self._egl_plugin = p.loadPlugin(path, "_eglRendererPlugin", physicsClientId=client)
            if self._egl_plugin < 0:
                self.world.close()
                raise RuntimeError("PyBullet's EGL renderer plugin could not be loaded (no EGL library?)")
        self.world.add_table(env_cfg.table)
        self.robot = p.loadURDF(urdf_for_pybullet(env_cfg.robot), basePosition=[0, 0, 0], useFixedBase=True,
                                physicsClientId=client)
        index = {}
        for joint in range(p.getNumJoints(self.robot, physicsClientId=client)):
            index[p.getJointInfo(self.robot, joint, physicsClientId=client)[1].decode()] = joint
        missing = [name for name in joint_names if name not in index]
        if missing:
            raise RuntimeError(f"urdf/{env_cfg.robot}.urdf lacks joints {missing}; regenerate it with `make meshes`")
        self.joint_index = {name: index[name] for name in joint_names}
        self.width, self.height, self.near, self.far = int(width), int(height), float(near), float(far)
        view = _GL_IN_OPTICAL @ np.linalg.inv(np.asarray(base_from_optical, dtype=float))
        # PyBullet takes OpenGL's column-major 16-vectors.
        self.view = view.T.reshape(-1).tolist()
        self.projection = np.asarray(projection, dtype=float).T.reshape(-1).tolist()
        self.renderer = renderer
        self._object_key: Optional[Tuple] = None
        self._scene_bodies: List[Tuple[Tuple, int]] = []  # (shape key, body) of set_objects' objects

    def set_joints(self, positions: Mapping[str, float]) -> None:
        """Pose the robot: joint name -> position (rad, or m for the fingers); unknown names are
        ignored, joints not given keep their pose."""
        for name, value in positions.items():
            joint = self.joint_index.get(name)
            if joint is not None:
                p.resetJointState(self.robot, joint, float(value), physicsClientId=self.client)

    def set_object(self, shape: str, dims: Tuple[float, ...], position: Sequence[float],
                   quaternion: Sequence[float]) -> None:
        """Place the object: ``shape`` "cylinder" (dims radius, height) or "box" (a cube's half
        extent, or a box's three),
        centre position (m) and quaternion (x, y, z, w) in base_link. A new body is made only
        when the shape or size changes."""
        key = (shape, tuple(round(float(d), 5) for d in dims))
        if key != self._object_key:
            self.world.set_object(shape, tuple(float(d) for d in dims), 0.1, 1.0)
            self._object_key = key
        p.resetBasePositionAndOrientation(self.world.object_id, list(position), list(quaternion),
                                          physicsClientId=self.client)

    def set_objects(self, objects: Sequence[Tuple[str, Tuple[float, ...], Sequence[float], Sequence[float]]]) -> None:
        """Place a scene of several objects, besides the one of :meth:`set_object` (which a scene
        leaves out of sight): each ``(shape, dims, position, quaternion)`` as :meth:`set_object`
        takes them. Bodies are kept while a scene's shapes stay the same, made anew otherwise.
        """
        keys = [(shape, tuple(round(float(d), 5) for d in dims)) for shape, dims, _, _ in objects]
        if keys != [key for key, _ in self._scene_bodies]:
            for _, body in self._scene_bodies:
                self.world.remove_body(body)
            self._scene_bodies = [(key, self.world.add_body(key[0], key[1], 0.0, 1.0)) for key in keys]
        if self.world.object_id is not None:  # the single object, out of the way
            p.resetBasePositionAndOrientation(self.world.object_id, [0.0, 0.0, -10.0], [0, 0, 0, 1],
                                              physicsClientId=self.client)
        for (_, body), (_, _, position, quaternion) in zip(self._scene_bodies, objects):
            p.resetBasePositionAndOrientation(body, list(position), list(quaternion), physicsClientId=self.client)

    def render(self) -> Tuple[np.ndarray, np.ndarray]:
        """One frame: ``(rgb, depth)``, rgb (H, W, 3) uint8, depth (H, W) float32 metres along
        the optical axis (0: nothing within the far plane)."""
        renderer = p.ER_BULLET_HARDWARE_OPENGL if self.renderer == "egl" else p.ER_TINY_RENDERER
        _, _, rgba, buffer, _ = p.getCameraImage(
            self.width, self.height, self.view, self.projection, renderer=renderer, shadow=0,
            flags=p.ER_NO_SEGMENTATION_MASK, physicsClientId=self.client)
        rgb = np.asarray(rgba, dtype=np.uint8).reshape(self.height, self.width, 4)[:, :, :3]
        buffer = np.asarray(buffer, dtype=np.float32).reshape(self.height, self.width)
        near, far = self.near, self.far
        # OpenGL's depth buffer is non-linear in distance; this inverts the projection above.
        depth = far * near / (far - (far - near) * buffer)
        depth[buffer >= 1.0] = 0.0
        return rgb, depth.astype(np.float32)

    def close(self) -> None:
        """Release the PyBullet client (safe to call twice)."""
        if self._egl_plugin >= 0 and self.world.client >= 0:
            p.unloadPlugin(self._egl_plugin, physicsClientId=self.client)
            self._egl_plugin = -1
        self.world.close()


def depth_to_millimetres(depth: np.ndarray, noise_per_m2: float = 0.0,
                         rng: Optional[np.random.Generator] = None) -> np.ndarray:
    """Depth (m, 0 = none) as a RealSense's aligned depth image: uint16 millimetres, 0 = no data.

    :param noise_per_m2: optional stereo-like noise: Gaussian with std ``noise_per_m2 * z**2``
        (m; a stereo camera's error grows with the square of the distance).
    :param rng: the noise generator (required when noise is on).
    """
    # float32 throughout: 0.5 mm steps need 17 bits of the 24 it has, and it is twice as fast.
    depth = np.asarray(depth, dtype=np.float32)
    if noise_per_m2 > 0.0:
        if rng is None:
            raise ValueError("depth noise needs a random generator")
        noisy = depth + rng.standard_normal(depth.shape, dtype=np.float32) * np.float32(noise_per_m2) * depth * depth
        depth = np.where(depth > 0.0, noisy, np.float32(0.0))
    millimetres = np.rint(depth * np.float32(1000.0))
    np.clip(millimetres, 0.0, 65535.0, out=millimetres)  # no data (0) and below stay 0
    return millimetres.astype(np.uint16)
