"""The energy account of a run: the external work by the trapezoidal rule, the stored energy and
the dissipation of blocks and joints, their balance error after every row, and the warnings that
say where an increment moved it."""
from __future__ import annotations

import warnings
from collections import namedtuple

import numpy as np

from ..kernels import relaxation as R
from ..kernels.joint_law import JS_DISS, JS_DISSF
from ..kernels.plastic_damage import MS_DISS

#: energies of an increment at its current state (:meth:`EnergyAccount.energies`)
Energies = namedtuple("Energies", "stored f_tot dw ratio diss element_diss joint_diss")
#: most warnings per run (per process) that name where an increment moved the energy balance
BALANCE_JUMPS = 3


class EnergyAccount:
    """External work, damped energy and the last row's external forces and displacements.

    Attributes: ``totals`` {"W_ext", "W_gross", "E_damped"} J (stored in checkpoints as meta
    ``energy``); ``f_prev`` (n_nodes, 3) N the external forces incl. reactions of the last row;
    ``u_committed`` (n_nodes, 3) m its displacements.
    """

    def __init__(self, n_nodes):
        self.totals = dict(W_ext=0.0, E_damped=0.0)
        self.f_prev = np.zeros((n_nodes, 3))
        self.u_committed = np.zeros((n_nodes, 3))
        self._balance = None   # [error (J) after the last increment, balance jumps reported]

    def energies(self, sim):
        """Forces and state at the current displacements and the energies of the increment so
        far, as :data:`Energies`: stored energy J, external forces incl. reactions (n_nodes, 3)
        N, work increment per DOF (n_nodes, 3) J, the increment's damage dissipation over the
        external work done, that dissipation J, and its whole dissipation by element
        (n_elements,) J and by joint point (nc,) J."""
        d, mesh, cont = sim.dyn, sim.mesh, sim.cont
        eint = R.internal_forces(mesh, cont, d)
        # external forces incl. reactions: applied loads on free DOFs, internal forces elsewhere
        f_tot = np.where(d.free > 0, d.fext + sim.lam[0] * d.P, d.fint)
        dw = 0.5 * (f_tot + self.f_prev) * (d.U - self.u_committed)
        element_diss = ((mesh.s_new[:, :, MS_DISS] - mesh.s_old[:, :, MS_DISS])
                        * mesh.wdet).sum(axis=1)
        joint_diss = (cont.s_new[:, JS_DISS] - cont.s_old[:, JS_DISS]) * cont.area
        ddiss = float(element_diss.sum())
        if cont.slave.size:
            dj = (cont.s_new[:, JS_DISS] - cont.s_new[:, JS_DISSF]
                  - cont.s_old[:, JS_DISS] + cont.s_old[:, JS_DISSF])
            ddiss += float(dj @ cont.area)
        w_ext = self.totals["W_ext"] + float(dw.sum())
        return Energies(eint, f_tot, dw, ddiss / w_ext if w_ext > 0 else 0.0, ddiss, element_diss,
                        joint_diss)

    def commit(self, energies, u):
        """Book an accepted increment's work (``energies`` of :meth:`energies`; ``u`` its
        displacements (n_nodes, 3) m)."""
        dw = energies.dw
        self.totals["W_ext"] += float(dw.sum())
        # gross work: the scale of the balance error when works of opposite sign cancel (rocking)
        self.totals["W_gross"] = self.totals.get("W_gross", 0.0) + float(np.abs(dw).sum())
        self.f_prev = energies.f_tot
        self.u_committed = u.copy()

    def columns(self, sim, stored, damped):
        """The history columns of the committed state (``stored`` J its stored energy,
        ``damped`` J the damping's work in the increment) and its balance error J."""
        mesh, cont = sim.mesh, sim.cont
        self.totals["E_damped"] += damped
        d_blocks = float((mesh.s_old[:, :, MS_DISS] * mesh.wdet).sum())
        off = sim.sliding.diss_off if sim.sliding is not None else np.zeros(2)
        d_joints = float(cont.s_old[:, JS_DISS] @ cont.area + off[0]) if cont.slave.size else 0.0
        d_friction = (float(cont.s_old[:, JS_DISSF] @ cont.area + off[1]) if cont.slave.size
                      else 0.0)
        w_ext = self.totals["W_ext"]
        err = w_ext - stored - d_blocks - d_joints
        gross = self.totals["W_gross"]
        return {"W_ext": w_ext, "E_stored": stored, "D_blocks": d_blocks, "D_joints": d_joints,
                "D_joint_damage": d_joints - d_friction, "D_joint_friction": d_friction,
                "E_damped": self.totals["E_damped"],
                "balance_error": err / gross if gross > 0 else 0.0}, err

    def serialise(self):
        """(arrays, meta) of a checkpoint."""
        return {"f_prev": self.f_prev}, {"energy": self.totals}

    def restore(self, arrays, meta, u):
        """From a checkpoint's ``arrays`` and ``meta``; ``u`` (n_nodes, 3) its displacements."""
        self.f_prev = arrays["f_prev"]
        self.totals = dict(meta["energy"])
        self.u_committed = u.copy()

    def audit(self, sim, row, err, joint_diss, element_diss):
        """Say once per run when the energy balance leaves its bound, and (at most
        ``BALANCE_JUMPS`` times) which joint points and element dissipated most in an increment
        that alone moved the error by more than the bound: ``err`` J the balance error after
        it, ``joint_diss`` (nc,) and ``element_diss`` (n_elements,) J its dissipation.

        The energy removed by the damping (history column ``E_damped``) is not part of the
        balance: each increment is applied as a step, and relaxing it to rest removes about
        half of (load step x displacement step), whatever the increment; it is reported only.
        """
        tol = sim.options.convergence.energy_tol
        gross = self.totals["W_gross"]
        if self._balance is None:   # the first increment of this process (a run or a resume)
            self._balance = [err, 0]
        jump = err - self._balance[0]
        self._balance[0] = err
        if gross > 0 and abs(jump) > tol * gross and self._balance[1] < BALANCE_JUMPS:
            self._balance[1] += 1
            c, blocks = sim.cont, sim.model.element_block
            top = [k for k in np.argsort(joint_diss)[::-1][:3] if joint_diss[k] > 0.0]
            e = int(np.argmax(element_diss))
            e = e if element_diss[e] > 0.0 else -1
            held = joint_diss[top].sum() + (element_diss[e] if e >= 0 else 0.0)
            where = "; ".join([f"joint point {k} (node {c.slave[k]}, blocks {_pair(sim, k)}) "
                               f"{joint_diss[k]:.3g} J" for k in top]
                              + ([f"element {e} (block {blocks[e]}) {element_diss[e]:.3g} J"]
                                 if e >= 0 else []))
            # a few points that booked most of the move point at them; otherwise the move is
            # the trapezoidal work rule's over a large step
            why = (f"most of it booked at {where}" if held >= 0.5 * abs(jump) else
                   f"no few points hold it (largest: {where or 'none'}), so it is the "
                   f"trapezoidal work rule's error over this step: use smaller increments")
            warnings.warn(f"increment {sim.increment}: the energy balance moved by {jump:.3g} J "
                          f"({jump / gross:.1%} of the gross work) in this one increment; {why}",
                          RuntimeWarning)
        err = abs(row["balance_error"])
        if err > tol and "energy" not in sim._warned:
            sim._warned.add("energy")
            warnings.warn(f"increment {sim.increment}: energy balance error {err:.2%} exceeds "
                          f"{tol:.2%}; use smaller increments (the trapezoidal "
                          f"work rule misses O(step^2) where joints open or close within an "
                          f"increment: docs/file_format.md) or tighten SolverOptions.tol",
                          RuntimeWarning)


def _pair(sim, k):
    """'slave-master' blocks of contact point ``k``, as paired now."""
    b = sim.sliding.blocks[k] if sim.sliding is not None else sim.model.contacts.blocks[k]
    return f"{b[0]}-{b[1]}"
