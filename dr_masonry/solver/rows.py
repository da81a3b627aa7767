"""Committing an accepted increment: the committed state, the history row (relaxation, energy,
damage, balance, reference points, node sets, contact reactions, sliding) and the observers that
take it."""
from __future__ import annotations

import numpy as np

from .. import loading as L
from ..kernels.joint_law import JS_D
from ..kernels.plastic_damage import MS_DC, MS_DT
from . import certificate as cert
from .arrays import mark_pristine


def commit(sim, out, elapsed, energies, balance, control=0, coarse=(0, 0)):
    """Accept the increment that ended with ``out`` (``R.Exit``; ``energies`` and ``balance``
    of its :data:`~.certificate.Verdict`; ``control``: what it ran under,
    ``controls.CONTROL_CODES``; ``coarse``: the coarse corrections its relaxation accepted and
    rejected): commit the state, make its history row and hand it to ``sim.observers``."""
    d, mesh, cont = sim.dyn, sim.mesh, sim.cont
    sim.energy.commit(energies, d.U)
    mesh.s_old[:] = mesh.s_new
    cont.s_old[:] = cont.s_new
    mark_pristine(sim)
    energy_columns, err = sim.energy.columns(sim, energies.stored, out.damped)
    sim.increment += 1
    balance_error = energy_columns.pop("balance_error")
    row = {"increment": sim.increment, "iterations": out.iterations, "residual": out.residual,
           "time_s": elapsed, "control": control, "lambda": float(sim.lam[0]),
           "cut_iterations": sim._cut_work[0], "cut_s": sim._cut_work[1],
           "coarse_accepted": coarse[0], "coarse_rejected": coarse[1],
           "dissipation_ratio": energies.ratio, **energy_columns, "E_kinetic": out.kinetic,
           "balance_error": balance_error}
    row.update(state_columns(sim, out, balance))
    row.update(reaction_columns(sim, balance))
    # finite sliding: re-pair for the next increment (this row's forces are those above)
    sl = sim.sliding
    row["contacts_moved"] = sl.update() if sl is not None else 0
    row["contacts_off"] = int((cont.area == 0.0).sum())
    row["contacts_sunk"] = int((sl.sunk > 0.0).sum()) if sl is not None else 0
    sim._cut_work = [0, 0.0]
    for key, v in row.items():
        sim.history.setdefault(key, [np.nan] * (sim.increment - 1)).append(float(v))
    sim.energy.audit(sim, row, err, energies.joint_diss, energies.element_diss)
    sim.last_row = row
    for obs in sim.observers:
        obs.row(sim, row)


def state_columns(sim, out, balance):
    """Damage maxima, overhang, block imbalance and the resultant against the driving force."""
    cont, mesh = sim.cont, sim.mesh
    row = {"max_joint_damage": float(cont.s_old[:, JS_D].max()) if cont.slave.size else 0.0,
           "max_dt": float(mesh.s_old[:, :, MS_DT].max()),   # (a model has elements)
           "max_dc": float(mesh.s_old[:, :, MS_DC].max()),
           "max_overhang": cert.check_overhang(sim),
           "block_imbalance": cert.check_block_balance(sim, out), "gap_ratio": balance.ratio}
    for k, name in enumerate("xyz"):
        row[f"gap.f{name}"] = balance.gap[k]
        row[f"drive.f{name}"] = balance.drive[k]
    cert.check_return_mapping(sim)
    return row


def reaction_columns(sim, balance):
    """Displacements and forces of the reference points, the prescribed node sets and the
    contact reactions."""
    d, cont = sim.dyn, sim.cont
    lam = float(sim.lam[0])
    rpres = balance.rpres
    row = {}
    for rp in sim.rigid_points:
        for name, k in L.DOFS.items():
            row[f"{rp.name}.u{name}"] = d.rpU[rp.index, k]
            row[f"{rp.name}.f{name}"] = (d.rpf[rp.index, k] + lam * d.rpP[rp.index, k]
                                         - rpres[rp.index, k])
    for (name, k), (nodes, kk) in sim.presc.items():
        row[f"{name}.u{'xyz'[k]}"] = float(d.U[nodes, k].mean())
        row[f"{name}.f{'xyz'[k]}"] = float((d.fint[nodes, k] - d.fext[nodes, k]).sum())
    fb = cont.fbuf.reshape(-1, 5, 3)
    for name, (sl, ms) in sim.contact_reactions.items():
        f = fb[sl, 0].sum(axis=0) + fb[ms, 1:].sum(axis=(0, 1))
        for k in range(3):
            row[f"{name}.f{'xyz'[k]}"] = float(f[k])
    return row
