"""paroct: tetrahedral meshes of closed solids from Todd's fat (BCC) triangulation."""

from .errors import ParoctError
from .mesher import MeshReport, MeshResult, TetMesh, mesh
from .surface import Surface, load_surface

__version__ = "0.1.0"

__all__ = ["ParoctError", "MeshReport", "MeshResult", "TetMesh", "Surface", "load_surface", "mesh", "__version__"]
