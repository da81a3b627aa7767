"""Collapse under load control: a tilting table ramped until the structure has no equilibrium.

A tilting table tilted by ``theta`` is gravity ``g`` along -z plus a horizontal body force
``lam g`` along +x on the same masses, ``lam = tan(theta)``. Past the collapse factor there is
no equilibrium: the increment does not converge, the solver halves it ``SolverOptions.max_cuts``
times and stops with a :class:`~dr_masonry.solver.SolverError` naming the increment (or it stops
at once on a run-away displacement). :func:`run_to_collapse` turns that stop into the run's
diagnosis: the last converged factor, the factor of the attempt that found no equilibrium, the
solver's message and the mechanism, the motion of that failed attempt (rigid blocks: their
rotations, :func:`block_rotations`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .loading import BodyForce, Gravity, Load, Stage
from .params import ParameterError
from .units import g as G

#: name of the tilting table's horizontal body force (its factor is ``lam = tan(theta)``)
TILT = "tilt"


@dataclass
class Collapse:
    """What :func:`run_to_collapse` found.

    ``stage``: the stage in which the structure lost equilibrium (None: it stood through every
    stage); ``factors``: (rows,) the tilt factor applied in every converged row (the ratio of the
    applied horizontal and vertical loads); ``reaction``: (rows,) the same factor from the
    support reaction, ``-R_x / R_z`` (equal to it within the residual tolerance); ``failed``: the
    tilt factor of the attempt that found no equilibrium (nan when it stood); ``message``: the
    solver's diagnosis; ``motion``: (n_nodes, 3) m, the displacement of the failed attempt from
    the last converged state (None when it stood)."""
    stage: str | None
    factors: np.ndarray
    reaction: np.ndarray
    failed: float
    message: str
    motion: np.ndarray | None

    @property
    def factor(self):
        """The tilt factor of the last converged row (0 if none converged)."""
        return float(self.factors[-1]) if self.factors.size else 0.0

    @property
    def collapsed(self):
        """Whether the structure lost equilibrium."""
        return self.stage is not None


def gravity_stage(increments=2):
    """The stage ``gravity``: self-weight applied in ``increments``."""
    return Stage("gravity", increments, [Load(pattern=Gravity(), to=1.0)])


def tilt_stages(lam_max, step, gravity_increments=2):
    """Stages of a tilting table: ``gravity`` (self-weight in ``gravity_increments``), then
    ``tilt``, the horizontal body force's factor ramped from 0 to ``lam_max`` in steps of
    ``step`` (the number of increments rounds ``lam_max / step`` up)."""
    if not (np.isfinite(lam_max) and lam_max > 0 and np.isfinite(step) and 0 < step <= lam_max):
        raise ParameterError(f"parameters step={step!r}, lam_max={lam_max!r}: the tilting "
                             f"table needs 0 < step <= lam_max")
    n = int(np.ceil(lam_max / step - 1e-9))
    return [gravity_stage(gravity_increments),
            Stage("tilt", n, [Load(pattern=BodyForce(accel=(G, 0.0, 0.0), name=TILT),
                                   to=n * step)])]


def run_to_collapse(sim, stages, reaction):
    """Run ``stages`` on ``sim`` (a :class:`~dr_masonry.Simulation` with a contact reaction named
    ``reaction`` between the moving blocks and their supports) and return a :class:`Collapse`.
    The stages load by self-weight and the tilt only (:func:`tilt_stages`): the factor of an
    attempt is the ratio of the applied horizontal and vertical loads, read by a monitor
    (``Simulation.monitors``) that also keeps the attempt's displacements.
    A :class:`~dr_masonry.solver.SolverError` is the collapse, not an error: the rows before it
    stay in the history (and the result file)."""
    from .solver import SolverError
    applied, failing = {}, {}

    def keep(s, info, done):   # the attempt in progress: its displacements and applied loads
        fext = s.dyn.fext      # the last attempt of a row is the one that was committed
        applied[s.increment] = -fext[:, 0].sum() / fext[:, 2].sum() if fext[:, 2].any() else 0.0
        failing["U"] = s.dyn.U.copy()
    sim.monitors.append(keep)
    stage, message = None, ""
    try:
        sim.run(stages)
    except SolverError as e:
        stage, message = sim.stage_name, str(e)
    finally:
        sim.monitors.remove(keep)
    hist = sim.history
    fx = np.asarray(hist.get(f"{reaction}.fx", []), dtype=float)
    fz = np.asarray(hist.get(f"{reaction}.fz", []), dtype=float)
    rows = sim.increment     # row k + 1 was relaxed while sim.increment was k
    factors = np.array([applied.get(k, np.nan) for k in range(rows)])
    from_reaction = np.where(fz != 0.0, -fx / np.where(fz != 0.0, fz, 1.0), 0.0)
    motion = failing["U"] - sim.dyn.U if stage is not None and "U" in failing else None
    failed = applied.get(rows, np.nan) if stage is not None else np.nan
    return Collapse(stage, factors, from_reaction, float(failed), message, motion)


def block_rotations(model, blocks, u, du):
    """Rotation (rad, positive from +x towards +z: counter-clockwise seen from -y) of each of
    ``blocks`` under the displacement increment ``du`` (n_nodes, 3) m from the state ``u``
    (n_nodes, 3) m: the least-squares rigid rotation of its nodes in the (x, z) plane."""
    out = np.empty(len(blocks))
    for k, b in enumerate(blocks):
        nd = model.block_nodes(b)
        a = (model.nodes[nd] + u[nd])[:, [0, 2]]
        a -= a.mean(axis=0)
        d = du[nd][:, [0, 2]]
        out[k] = np.sum(a[:, 0] * d[:, 1] - a[:, 1] * d[:, 0]) / np.sum(a * a)
    return out


def draw_mechanism(ax, model, blocks, u, motion, scale):
    """Draw on ``ax`` the (x, z) outline (the corners 0, 1, 5, 4 of each block: its y = min face)
    of ``blocks`` at rest (grey) and, for those that move, displaced by ``u + scale * motion``
    (blue; ``u``, ``motion``: (n_nodes, 3) m)."""
    for b in blocks:
        corners = model.block_corners[b][[0, 1, 5, 4]]
        ax.fill(*corners[:, [0, 2]].T, fc="0.85", ec="0.5", lw=0.6)
        if model.block_fixed[b]:
            continue
        nd = model.block_nodes(b)
        k = nd[[int(np.argmin(np.linalg.norm(model.nodes[nd] - c, axis=1))) for c in corners]]
        moved = corners + u[k] + scale * motion[k]
        ax.fill(*moved[:, [0, 2]].T, fc="none", ec="tab:blue", lw=1.0)
