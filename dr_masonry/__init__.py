"""dr_masonry: damaging block-based masonry (D'Altri et al. 2019) by explicit dynamic relaxation.

Public API: build a :class:`Model` of blocks (``dr_masonry.geometry`` has wall and house
generators), give it a :class:`JointLaw`, wrap it in a :class:`Simulation` with supports and rigid
reference points, and run a list of :class:`Stage` objects of controls. Single-point drivers
(:func:`drive_joint`, :func:`drive_material`) exercise the same kernels the solver uses.
"""
from . import units
from .model import Model, ModelError
from .materials import JointLaw, PlasticDamage
from .loading import (Displacement, Force, Load, Indirect, Opening, Stage, Gravity, BodyForce,
                      Pressure, PointLoad, Combined, Until, cyclic_path)
from .options import SolverOptions
from .solver import Simulation, SolverError
from .drivers_joint import drive_joint
from .drivers_material import drive_material, drive_strain_path

__version__ = "0.3.1"
__all__ = ["units", "Model", "ModelError", "JointLaw", "PlasticDamage", "Displacement", "Force",
           "Load", "Indirect", "Opening", "Stage", "Until", "Gravity", "BodyForce", "Pressure",
           "PointLoad", "Combined", "cyclic_path", "Simulation", "SolverOptions", "SolverError",
           "drive_joint", "drive_material", "drive_strain_path"]
