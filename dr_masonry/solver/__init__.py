"""The solver: :class:`Simulation` (set-up, ``run``, ``resume``) and the modules it drives
(see ``simulation``'s docstring for which holds what)."""
from .arrays import SolverError
from .simulation import Simulation

__all__ = ["Simulation", "SolverError"]
