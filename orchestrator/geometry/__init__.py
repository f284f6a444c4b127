"""Triangle meshes for the scenes, generated with numpy and written with meshio.

Every solid is a closed, consistently oriented, manifold triangle shell (each edge in exactly two
triangles, traversed once in each direction; Euler characteristic 2 per shell). A piston is a plate
(a closed puck) plus six vanes, each vane its *own* closed box that starts off the axis and dips
into the plate: no vertex or edge is shared between shells, so nothing is non-manifold (LIGGGHTS
crashed with ``double free`` and hung on vanes meeting on the axis or sharing edges with the plate).
"""
from .mesh import (Mesh, box, check_manifold, cylinder_shell, vaned_piston, write_stl, read_stl,
                   MeshError)

__all__ = ["Mesh", "box", "check_manifold", "cylinder_shell", "vaned_piston", "write_stl", "read_stl",
           "MeshError"]
