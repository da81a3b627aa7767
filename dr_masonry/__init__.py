"""dr_masonry: damaging block-based masonry (D'Altri et al. 2019) by explicit dynamic relaxation.

Public API: build a :class:`Model` of blocks (``dr_masonry.geometry`` has wall and house
generators), give it a :class:`JointLaw`, wrap it in a :class:`Simulation` with supports and rigid
reference points, and run a list of :class:`Stage` objects of controls. Single-point drivers
(:func:`drive_joint`, :func:`drive_material`) exercise the same kernels the solver uses.
"""
import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # before Numba starts its thread pool

from . import units  # noqa: E402
from .model import Model, ModelError  # noqa: E402
from .materials import JointLaw, PlasticDamage  # noqa: E402
from .loading import (Displacement, Force, Load, Indirect, Stage, Gravity, BodyForce,  # noqa: E402
                      Pressure, PointLoad, Combined, cyclic_path)
from .solver import Simulation, SolverOptions, SolverError  # noqa: E402
from .drivers_joint import drive_joint  # noqa: E402
from .drivers_material import drive_material, drive_strain_path  # noqa: E402

__version__ = "0.1.0"
__all__ = ["units", "Model", "ModelError", "JointLaw", "PlasticDamage", "Displacement", "Force",
           "Load", "Indirect", "Stage", "Gravity", "BodyForce", "Pressure", "PointLoad", "Combined",
           "cyclic_path", "Simulation", "SolverOptions", "SolverError", "drive_joint",
           "drive_material", "drive_strain_path"]
