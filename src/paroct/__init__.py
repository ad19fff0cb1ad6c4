"""paroct: tetrahedral meshes of closed solids from Todd's fat (BCC) triangulation."""

from .boundary import BoundaryPatches, boundary_patches, surface_patches
from .errors import ParoctError
from .mesher import MeshReport, MeshResult, TetMesh, mesh
from .sizing import Box, Sphere
from .surface import Surface, load_surface, surface_from_arrays

__version__ = "0.1.0"

__all__ = ["BoundaryPatches", "Box", "MeshReport", "MeshResult", "ParoctError", "Sphere", "Surface", "TetMesh", "__version__", "boundary_patches", "load_surface", "mesh", "surface_from_arrays", "surface_patches"]
