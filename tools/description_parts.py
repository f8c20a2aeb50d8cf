"""The building blocks of tools/generate_description.py: URDF collision primitives, revolved
and boxed visual parts (trimesh), the link and joint records, mass properties, number formatting.

Imported by the generator as a sibling module (``python tools/generate_description.py``)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import trimesh

Vec3 = Tuple[float, float, float]
SECTIONS = 48                          # facets around a revolved part (mesh size vs. looks)


# =========================================================================== primitives
@dataclass(frozen=True)
class Prim:
    """A URDF collision primitive, axis-aligned in its link frame.

    kind: "cylinder" (along ``axis``, ``radius``, ``length``) or "box" (``size`` =
    full extents along x, y, z). ``center`` is the primitive's centre in the link
    frame (m).
    """

    kind: str
    center: Vec3
    axis: str = "z"
    radius: float = 0.0
    length: float = 0.0
    size: Vec3 = (0.0, 0.0, 0.0)

    def aabb(self) -> Tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounds (lo, hi) in the link frame (m)."""
        c = np.array(self.center)
        if self.kind == "box":
            half = np.array(self.size) / 2.0
        else:
            half = np.full(3, self.radius)
            half["xyz".index(self.axis)] = self.length / 2.0
        return c - half, c + half

    def contains(self, p: np.ndarray) -> np.ndarray:
        """Boolean mask of the points ``p`` (N x 3, link frame, m) inside the primitive."""
        d = p - np.array(self.center)
        if self.kind == "box":
            half = np.array(self.size) / 2.0
            return np.all(np.abs(d) <= half, axis=1)
        k = "xyz".index(self.axis)
        radial = np.delete(d, k, axis=1)
        return (np.abs(d[:, k]) <= self.length / 2.0) & (
            np.einsum("ij,ij->i", radial, radial) <= self.radius**2)

    def urdf(self) -> str:
        """The <origin> and <geometry> lines of a <collision> element."""
        # URDF cylinders run along their own z: turn them onto the wanted axis.
        rpy = {"z": (0.0, 0.0, 0.0), "x": (0.0, math.pi / 2, 0.0),
               "y": (math.pi / 2, 0.0, 0.0)}[self.axis if self.kind == "cylinder" else "z"]
        if self.kind == "box":
            geom = f'<box size="{vec(self.size)}"/>'
        else:
            geom = f'<cylinder radius="{num(self.radius)}" length="{num(self.length)}"/>'
        return (f'<origin xyz="{vec(self.center)}" rpy="{vec(rpy)}"/>\n'
                f"      <geometry>{geom}</geometry>")


def cyl(axis: str, lo: float, hi: float, radius: float,
        at: Vec3 = (0.0, 0.0, 0.0)) -> Prim:
    """Cylinder along link ``axis`` from ``lo`` to ``hi`` (m); the other two centre
    coordinates are taken from ``at`` (its component along ``axis`` is ignored)."""
    c = list(at)
    c["xyz".index(axis)] = (lo + hi) / 2.0
    return Prim("cylinder", tuple(c), axis=axis, radius=radius, length=hi - lo)


def box(lo: Vec3, hi: Vec3) -> Prim:
    """Axis-aligned box between the corners ``lo`` and ``hi`` (link frame, m)."""
    return Prim("box", tuple((a + b) / 2.0 for a, b in zip(lo, hi)),
                size=tuple(b - a for a, b in zip(lo, hi)))


# =========================================================================== visual parts
def _z_to(axis: str) -> np.ndarray:
    """4x4 rotation taking the local +z axis onto link axis ``axis`` (x, y or z)."""
    if axis == "x":
        return trimesh.transformations.rotation_matrix(math.pi / 2, [0, 1, 0])
    if axis == "y":
        return trimesh.transformations.rotation_matrix(-math.pi / 2, [1, 0, 0])
    return np.eye(4)


def _place(mesh: trimesh.Trimesh, axis: str, at: Vec3) -> trimesh.Trimesh:
    """Turn a z-built part onto ``axis`` and move it so that its local origin is at
    ``at`` except along ``axis``, where the built coordinates are kept."""
    mesh.apply_transform(_z_to(axis))
    offset = np.array(at, dtype=float)
    offset["xyz".index(axis)] = 0.0
    mesh.apply_translation(offset)
    return mesh


def _arc(cx: float, cz: float, r: float, a0: float, a1: float, n: int) -> List[List[float]]:
    """``n`` points (radius, z) on an arc of a revolve profile: centre (cx, cz), radius
    ``r`` (m), from angle ``a0`` to ``a1`` (rad, measured from the +radius direction)."""
    return [[cx + r * math.cos(a), cz + r * math.sin(a)]
            for a in np.linspace(a0, a1, n)]


def v_cyl(axis: str, lo: float, hi: float, radius: float, at: Vec3 = (0.0, 0.0, 0.0),
          fillet: float = 0.004) -> trimesh.Trimesh:
    """Visual cylinder along ``axis`` from ``lo`` to ``hi`` (m) with rounded rims
    (``fillet`` m) so that housings do not look like raw CAD primitives."""
    f = min(fillet, radius / 2.0, (hi - lo) / 2.0)
    profile = ([[0.0, lo]] + _arc(radius - f, lo + f, f, -math.pi / 2, 0.0, 4)
               + _arc(radius - f, hi - f, f, 0.0, math.pi / 2, 4) + [[0.0, hi]])
    return _place(trimesh.creation.revolve(np.array(profile), sections=SECTIONS), axis, at)


def v_tube(axis: str, lo: float, hi: float, r_lo: float, r_hi: float,
           at: Vec3 = (0.0, 0.0, 0.0)) -> trimesh.Trimesh:
    """Capsule-like, slightly tapered link tube along ``axis``: hemispherical ends of
    radius ``r_lo`` centred at ``lo`` and ``r_hi`` centred at ``hi`` (m)."""
    profile = ([[0.0, lo - r_lo]] + _arc(0.0, lo, r_lo, -math.pi / 2, 0.0, 9)[1:]
               + _arc(0.0, hi, r_hi, 0.0, math.pi / 2, 9)[:-1] + [[0.0, hi + r_hi]])
    return _place(trimesh.creation.revolve(np.array(profile), sections=SECTIONS), axis, at)


def v_rbox(lo: Vec3, hi: Vec3, axis: str = "z", radius: float = 0.006) -> trimesh.Trimesh:
    """Box between ``lo`` and ``hi`` (link frame, m) whose edges parallel to ``axis``
    are rounded with ``radius`` (an extruded rounded rectangle)."""
    k = "xyz".index(axis)
    lo_a, hi_a = np.array(lo, float), np.array(hi, float)
    # In-plane axes of the rounded rectangle, ordered so that (u, v, axis) is right-handed.
    u, v = [(1, 2), (2, 0), (0, 1)][k]
    hu, hv = (hi_a[u] - lo_a[u]) / 2.0, (hi_a[v] - lo_a[v]) / 2.0
    r = min(radius, hu, hv)
    ring = []
    for cu, cv, a0 in ((hu - r, hv - r, 0.0), (-hu + r, hv - r, 90.0),
                       (-hu + r, -hv + r, 180.0), (hu - r, -hv + r, 270.0)):
        for a in np.radians(np.linspace(a0, a0 + 90.0, 5)):
            ring.append((cu + r * math.cos(a), cv + r * math.sin(a)))
    n = len(ring)
    verts = []
    for w in (lo_a[k], hi_a[k]):
        for pu, pv in ring:
            p = [0.0, 0.0, 0.0]
            p[u], p[v], p[k] = pu, pv, w
            verts.append(p)
    verts.append([0.0, 0.0, 0.0])
    verts[-1][k] = lo_a[k]
    verts.append([0.0, 0.0, 0.0])
    verts[-1][k] = hi_a[k]
    faces = []
    for i in range(n):
        j = (i + 1) % n
        faces += [[i, j, n + j], [i, n + j, n + i]]          # side (outward normals)
        faces += [[2 * n, j, i], [2 * n + 1, n + i, n + j]]  # bottom / top fans
    mesh = trimesh.Trimesh(np.array(verts), np.array(faces), process=False)
    centre = (lo_a + hi_a) / 2.0
    centre[k] = 0.0
    mesh.apply_translation(centre)
    return mesh


# =========================================================================== link model
@dataclass
class LinkSpec:
    """One URDF link: mass (kg), collision primitives and visual parts (link frame)."""

    name: str
    mass: float
    collisions: List[Prim] = field(default_factory=list)
    white: List[trimesh.Trimesh] = field(default_factory=list)
    dark: List[trimesh.Trimesh] = field(default_factory=list)
    contact: bool = False


@dataclass
class JointSpec:
    """One URDF joint; ``xyz`` in metres and ``rpy`` in radians in the parent frame."""

    name: str
    kind: str
    parent: str
    child: str
    xyz: Sequence[float]
    rpy: Sequence[float]
    axis: Optional[Vec3] = None
    limit: Optional[Dict[str, float]] = None


@dataclass(frozen=True)
class MassProps:
    """Mass (kg), centre of mass (m, link frame) and inertia tensor about the COM
    (kg m^2, link-frame axes)."""

    mass: float
    com: np.ndarray
    inertia: np.ndarray


def mass_properties(prims: Sequence[Prim], mass: float, n_cells: int = 400_000) -> MassProps:
    """Mass properties of the union of ``prims`` with total ``mass`` (kg).

    Midpoint-rule quadrature on a regular grid over the union's bounds: overlaps are
    counted once (unlike summing primitives), and the result is the inertia of a
    genuine mass distribution, hence positive definite and triangle-consistent.
    Values are rounded (COM to 1e-6 m, inertia to 6 significant digits) so that the
    written URDF does not depend on floating-point summation order.
    """
    bounds = [p.aabb() for p in prims]
    lo = np.min([b[0] for b in bounds], axis=0)
    hi = np.max([b[1] for b in bounds], axis=0)
    ext = hi - lo
    h0 = (float(np.prod(ext)) / n_cells) ** (1.0 / 3.0)
    counts = np.maximum(np.ceil(ext / h0).astype(int), 2)
    h = ext / counts
    axes = [lo[i] + (np.arange(counts[i]) + 0.5) * h[i] for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    inside = np.zeros(len(grid), dtype=bool)
    for p in prims:
        inside |= p.contains(grid)
    pts = grid[inside]
    cell_mass = mass / len(pts)
    com = pts.mean(axis=0)
    d = pts - com
    second = d.T @ d * cell_mass                     # sum m d d^T
    inertia = np.trace(second) * np.eye(3) - second
    # Each cell is a small box, not a point: add its own inertia (m (a^2 + b^2) / 12).
    inertia += mass * np.diag([h[1] ** 2 + h[2] ** 2, h[0] ** 2 + h[2] ** 2,
                               h[0] ** 2 + h[1] ** 2]) / 12.0
    # Symmetric shapes give exact zeros up to float noise; snap that noise to 0 so the
    # text does not depend on summation order, then keep 6 significant digits.
    com = np.round(com, 6) + 0.0
    scale = float(np.trace(inertia))
    inertia = np.where(np.abs(inertia) < 1e-7 * scale, 0.0, inertia)
    inertia = np.array([[float(f"{x:.6g}") for x in row] for row in inertia])
    inertia = (inertia + inertia.T) / 2.0
    w = np.linalg.eigvalsh(inertia)
    assert w.min() > 0.0, "inertia not positive definite"
    assert w.sum() - 2.0 * w.max() >= -1e-12, "inertia violates the triangle inequality"
    return MassProps(mass, com, inertia)


# =========================================================================== formatting
def num(x: float) -> str:
    """Compact, stable decimal text for a float (no '-0')."""
    s = f"{float(x):.9g}"
    return "0" if s in ("-0", "0", "-0.0") else s


def vec(v: Sequence[float]) -> str:
    """Space-separated ``num`` of a vector."""
    return " ".join(num(x) for x in v)
