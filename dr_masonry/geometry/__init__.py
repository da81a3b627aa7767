"""Generators on top of :meth:`Model.add_block`: walls and bonds, openings, corners, beams,
slabs, the terraced house. SI units (m); axes x along a wall, y through it, z up."""
from .arch import Arch, add_arch
from .beams import DEFAULT_ELEMENT_SIZE, add_beam, add_foundation, add_slab, plane_nodes
from .house import HouseLayout, HouseParams, terraced_house
from .walls import BrickSpec, GeometryError, Lintel, Opening, Wall, add_corner, add_wall

__all__ = ["Arch", "add_arch",
           "BrickSpec", "GeometryError", "Lintel", "Opening", "Wall", "add_wall", "add_corner",
           "DEFAULT_ELEMENT_SIZE", "add_beam", "add_foundation", "add_slab", "plane_nodes",
           "HouseParams", "HouseLayout", "terraced_house"]
