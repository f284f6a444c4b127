"""Closed triangle shells (numpy) and their manifold/closed check. Lengths in metres."""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


class MeshError(ValueError):
    """A mesh that is not closed, not manifold or not consistently oriented."""


@dataclass
class Mesh:
    """Vertices (V, 3) [m] and triangles (T, 3) (vertex indices, counter-clockwise seen from
    outside, so normals point outwards). ``shells`` lists the triangle index ranges of the
    separate closed shells it was built from (for reporting)."""
    vertices: np.ndarray
    triangles: np.ndarray
    shells: list = field(default_factory=list)

    def __add__(self, other: "Mesh") -> "Mesh":
        off = len(self.vertices)
        toff = len(self.triangles)
        return Mesh(np.vstack([self.vertices, other.vertices]),
                    np.vstack([self.triangles, other.triangles + off]),
                    list(self.shells) + [(a + toff, b + toff) for a, b in other.shells])

    def rotated_z(self, angle: float) -> "Mesh":
        c, s = math.cos(angle), math.sin(angle)
        R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
        return Mesh(self.vertices @ R.T, self.triangles.copy(), list(self.shells))

    def translated(self, d) -> "Mesh":
        return Mesh(self.vertices + np.asarray(d, dtype=float), self.triangles.copy(), list(self.shells))

    def flipped_z(self) -> "Mesh":
        """Mirror through z = 0 (triangle order reversed to keep normals outward)."""
        v = self.vertices * np.array([1, 1, -1.0])
        return Mesh(v, self.triangles[:, ::-1].copy(), list(self.shells))

    @property
    def bounds(self):
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    def volume(self) -> float:
        """Enclosed volume [m³] (sum over shells; overlapping shells count twice)."""
        a, b, c = (self.vertices[self.triangles[:, k]] for k in range(3))
        return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def _single(v, t) -> Mesh:
    t = np.asarray(t, dtype=np.int64)
    return Mesh(np.asarray(v, dtype=float), t, [(0, len(t))])


def box(x0, x1, y0, y1, z0, z1) -> Mesh:
    """Axis-aligned closed box."""
    v = np.array([[x, y, z] for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)], dtype=float)
    # vertex k = x + 2y + 4z
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    t = []
    for a, b, c, d in quads:
        t += [(a, b, c), (a, c, d)]
    return _single(v, t)


def cylinder_shell(radius: float, z0: float, z1: float, n_seg: int, max_aspect: float = 3.0) -> Mesh:
    """Closed cylinder (side and both end caps) about the z axis. The side is split into rings so
    that no side triangle is more than ``max_aspect`` times taller than wide; the caps are fans
    around a centre vertex."""
    if n_seg < 8:
        raise ValueError("n_seg must be >= 8")
    chord = 2 * radius * math.sin(math.pi / n_seg)
    n_z = max(1, int(math.ceil((z1 - z0) / (max_aspect * chord))))
    th = 2 * math.pi * np.arange(n_seg) / n_seg
    zs = np.linspace(z0, z1, n_z + 1)
    ring = np.stack([radius * np.cos(th), radius * np.sin(th)], axis=1)
    v = [np.column_stack([ring, np.full(n_seg, z)]) for z in zs]
    v.append([[0.0, 0.0, z0], [0.0, 0.0, z1]])
    v = np.vstack(v)
    cb, ct = len(v) - 2, len(v) - 1
    t = []
    for k in range(n_z):
        for i in range(n_seg):
            j = (i + 1) % n_seg
            a, b = k * n_seg + i, k * n_seg + j
            c, d = a + n_seg, b + n_seg
            t += [(a, b, d), (a, d, c)]
    top = n_z * n_seg
    for i in range(n_seg):
        j = (i + 1) % n_seg
        t.append((cb, j, i))            # bottom cap, normal -z
        t.append((ct, top + i, top + j))  # top cap, normal +z
    return _single(v, t)


def vaned_piston(radius: float, plate_thickness: float, n_seg: int, vane_height: float,
                 vane_thickness: float, vane_inner_radius: float, n_vanes: int = 6,
                 vane_embed: float | None = None, flange_radius: float | None = None,
                 flange_thickness: float | None = None) -> Mesh:
    """A piston facing +z: plate z ∈ [-plate_thickness, 0] of radius ``radius`` and ``n_vanes``
    vanes in a star standing on it, z ∈ [-embed, vane_height], radially from
    ``vane_inner_radius`` to where the vane's outer corners reach ``radius``. Each vane is a
    separate closed box dipping ``vane_embed`` (default half the plate thickness) into the plate,
    so it shares no edge with the plate, and starts off the axis, so vanes never meet there
    (needs vane_inner_radius > vane_thickness / (2 sin(π/n_vanes))).

    ``flange_radius``: an optional wider disc (its own closed shell) under the plate,
    z ∈ [-plate_thickness - flange_thickness, -plate_thickness/2], which closes the gap between
    plate edge and sidewall at the plate's back: the gap becomes a pocket of depth
    ``plate_thickness`` that particles can enter but not pass."""
    if vane_embed is None:
        vane_embed = 0.5 * plate_thickness
    if not 0 < vane_embed < plate_thickness:
        raise ValueError("vane_embed must lie in (0, plate_thickness)")
    meet = vane_thickness / (2 * math.sin(math.pi / n_vanes))
    if vane_inner_radius <= meet * 1.05:
        raise ValueError(f"vane_inner_radius {vane_inner_radius:.3e} m must exceed {meet:.3e} m, or "
                         "neighbouring vanes would meet near the axis")
    x_out = math.sqrt(radius ** 2 - (vane_thickness / 2) ** 2)
    if x_out <= vane_inner_radius:
        raise ValueError("vane_inner_radius must be smaller than the piston radius")
    m = cylinder_shell(radius, -plate_thickness, 0.0, n_seg, max_aspect=20.0)
    if flange_radius is not None:
        if flange_radius <= radius:
            raise ValueError("flange_radius must exceed the plate radius")
        ft = flange_thickness if flange_thickness is not None else plate_thickness
        m = m + cylinder_shell(flange_radius, -plate_thickness - ft, -plate_thickness / 2, n_seg, max_aspect=20.0)
    if vane_height > 0:
        vane = box(vane_inner_radius, x_out, -vane_thickness / 2, vane_thickness / 2, -vane_embed, vane_height)
        for k in range(n_vanes):
            m = m + vane.rotated_z(2 * math.pi * k / n_vanes)
    return m


def check_manifold(mesh: Mesh, name: str = "mesh", raise_error: bool = True) -> dict:
    """Check that ``mesh`` is made of closed, manifold, consistently oriented shells: no degenerate
    or duplicate triangles, every undirected edge in exactly two triangles, every directed edge
    once (consistent orientation), no vertex shared by two shells (no pinch points), each shell
    with Euler characteristic 2 (a closed sphere-like surface) and positive volume (normals
    outwards). Returns a report dict; raises :class:`MeshError` listing the faults."""
    v, t = mesh.vertices, mesh.triangles
    faults = []
    if not np.all(np.isfinite(v)):
        faults.append("non-finite vertex coordinates")
    if t.min() < 0 or t.max() >= len(v):
        faults.append("triangle refers to a missing vertex")
    # duplicate vertices (distinct indices, same point) make edges look open
    scale = max(float(np.ptp(v)), 1e-300)
    q = np.round(v / (scale * 1e-9)).astype(np.int64)
    _, inv, counts = np.unique(q, axis=0, return_inverse=True, return_counts=True)
    if np.any(counts > 1):
        faults.append(f"{int(np.sum(counts > 1))} duplicated vertex positions")
    deg = (t[:, 0] == t[:, 1]) | (t[:, 1] == t[:, 2]) | (t[:, 0] == t[:, 2])
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    deg |= area <= (scale ** 2) * 1e-18
    if np.any(deg):
        faults.append(f"{int(deg.sum())} degenerate triangles")
    st = np.sort(t, axis=1)
    if len(np.unique(st, axis=0)) != len(t):
        faults.append("duplicate triangles")
    directed = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    und = np.sort(directed, axis=1)
    _, ucount = np.unique(und, axis=0, return_counts=True)
    n_open = int(np.sum(ucount == 1))
    n_nonmanifold = int(np.sum(ucount > 2))
    if n_open:
        faults.append(f"{n_open} open (boundary) edges: not watertight")
    if n_nonmanifold:
        faults.append(f"{n_nonmanifold} non-manifold edges (in more than two triangles)")
    _, dcount = np.unique(directed, axis=0, return_counts=True)
    if np.any(dcount > 1):
        faults.append(f"{int(np.sum(dcount > 1))} edges traversed twice in the same direction: "
                      "inconsistent orientation")
    # shells = connected components over shared vertices
    parent = np.arange(len(v))

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x
    for tri in t:
        ra = find(tri[0])
        for k in (1, 2):
            rb = find(tri[k])
            if rb != ra:
                parent[rb] = ra
    roots = np.array([find(x) for x in t[:, 0]])
    shells = []
    for r in np.unique(roots):
        tt = t[roots == r]
        verts = np.unique(tt)
        edges = np.unique(np.sort(np.concatenate([tt[:, [0, 1]], tt[:, [1, 2]], tt[:, [2, 0]]]), axis=1), axis=0)
        chi = len(verts) - len(edges) + len(tt)
        aa, bb, cc = v[tt[:, 0]], v[tt[:, 1]], v[tt[:, 2]]
        vol = float(np.einsum("ij,ij->i", aa, np.cross(bb, cc)).sum() / 6.0)
        shells.append({"triangles": int(len(tt)), "euler": int(chi), "volume": vol})
        if chi != 2:
            faults.append(f"a shell has Euler characteristic {chi} (a closed genus-0 shell has 2): "
                          "pinched or holed")
        if vol <= 0:
            faults.append("a shell has non-positive volume: normals point inwards")
    # vertices used by triangles of two different shells would already join them: check pinch
    # points (a vertex whose triangle fan is not a single disc) via vertex-edge counts
    report = {"name": name, "vertices": int(len(v)), "triangles": int(len(t)), "shells": shells,
              "closed": n_open == 0, "manifold": n_nonmanifold == 0 and not np.any(dcount > 1),
              "faults": faults}
    if faults and raise_error:
        raise MeshError(f"{name}: " + "; ".join(faults))
    return report


def write_stl(mesh: Mesh, path, name: str = "solid", check: bool = True) -> Path:
    """Write an ASCII STL (both LIGGGHTS' fix mesh/surface and YADE's ymport.stl read it)
    atomically, after :func:`check_manifold` when ``check``."""
    import meshio
    if check:
        check_manifold(mesh, name)
    path = Path(path)
    tmp = path.with_name(path.name + ".partial.stl")
    meshio.write(str(tmp), meshio.Mesh(mesh.vertices, [("triangle", mesh.triangles)]), file_format="stl",
                 binary=False)
    os.replace(tmp, path)
    return path


def read_stl(path) -> Mesh:
    """Read an STL back (meshio merges coincident vertices)."""
    import meshio
    # meshio first tests for a binary STL by multiplying the header's triangle count, a numpy
    # uint32, by 50; on an ASCII file (ours, LIGGGHTS' dumps) that count is text and the product
    # overflows harmlessly before meshio reads the file as ASCII: no RuntimeWarning for it
    with np.errstate(over="ignore"):
        m = meshio.read(str(path))
    tri = np.vstack([c.data for c in m.cells if c.type == "triangle"])
    return Mesh(np.asarray(m.points, dtype=float), tri.astype(np.int64), [(0, len(tri))])
