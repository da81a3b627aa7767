"""Finite sliding of the joints: contact points re-paired as slave nodes slide off their quads.

The contact points are paired once, in the reference configuration (``contact_search``); their
gap is measured from a fixed master point, which is exact while the slave node stays over its
master quad. After every committed increment, :class:`Sliding` looks for the points whose slave
node now projects outside its quad by more than ``SWITCH`` (natural coordinates beyond +-1, on
top of where it started, as a partial overlap can put a node outside) and hands them to
:func:`contact_search.redetect`: each moves to the quad
under its node, on the same block or the next one, with the local gap [u, d1, d2] unchanged at the
switch, so the joint history (damage, plastic slip) carries over and the forces stay continuous.
A node that slid beyond the end of every face by more than half an element is off the surface:
its point gets area 0 (no force, no stiffness) until a face takes it again. Nothing runs while no
node leaves its quad (one projection of the slave nodes per increment); the masses, the node
maps of the gather and the coarse operator are refreshed only when the set changes.

The number of points stays fixed, so every contact array and frame field keeps its shape; frames
written after the first change carry the contact set valid for them (docs/file_format.md).
"""
from __future__ import annotations

import numpy as np

from .contact_search import ContactSet, project_bilinear, redetect
from .kernels.joint_law import JS_DISS, JS_DISSF

#: how far (natural coordinates beyond +-1: 0.1 is 5 % of the quad's edge) a slave node must
#: have slid out of its quad before its point is re-paired. Nodes that start on the edge between
#: two quads (most of them) would otherwise switch back and forth at every micro-slip, and each
#: switch moves forces between the quads' nodes: on the S6 wall five such switches at its peak
#: sent the post-peak path elsewhere at three times the iterations (BENCHMARKS.md, section 21)
SWITCH = 0.1


class Sliding:
    """Re-pairing state of a :class:`~dr_masonry.solver.Simulation`'s contact set (after build).

    Attributes
    ----------
    area0 : (nc,) m^2 tributary areas as detected (``cont.area`` is 0 where a point is off).
    blocks : (nc, 2) (slave, master) block of every point, current.
    outside0 : (nc,) how far (natural coordinates beyond 1) each slave node projected outside
        its quad when last paired; a point is re-paired once it is ``SWITCH`` further out.
    diss_off : (2,) J joint dissipation (all, friction) of the points that are off the surface
        (their area is 0, so the sums over ``cont.area`` miss it), with the elastic energy each
        held when it went off (released, counted with the dissipation, not the friction).
    changed : bool, whether the set differs from ``model.contacts``.
    """

    def __init__(self, sim):
        self.sim = sim
        c = sim.model.contacts
        self.area0 = c.area.copy()
        self.blocks = c.blocks.copy()
        x = sim.model.nodes
        self.outside0 = self._outside(x) if c.n else np.zeros(0)
        self.diss_off = np.zeros(2)
        self.changed = False

    def _outside(self, x):
        cont = self.sim.cont
        r, s = project_bilinear(x[cont.master], x[cont.slave])
        return np.maximum(np.maximum(np.abs(r), np.abs(s)) - 1.0, 0.0)

    def contact_set(self, area=None):
        """The current contact set (areas 0 where a point is off the surface, or ``area``)."""
        c = self.sim.cont
        return ContactSet(c.slave, c.master, c.xi, c.area if area is None else area, c.law,
                          self.blocks, c.gap0)

    def update(self):
        """Re-pair the points whose slave node slid off its quad at the current (committed)
        displacements; returns the number of points re-paired, dropped or taken back."""
        sim = self.sim
        cont = sim.cont
        if cont.slave.size == 0:
            return 0
        x = sim.dyn.X + sim.dyn.U
        out = self._outside(x)
        cand = (out > self.outside0 + SWITCH) | (cont.area == 0.0)
        if not cand.any():
            return 0
        new, src = redetect(sim.model, self.contact_set(self.area0), x, rows=cand)
        area = np.zeros_like(self.area0)
        area[src] = new.area
        master, xi, gap0 = cont.master.copy(), cont.xi.copy(), cont.gap0.copy()
        law, blocks = cont.law.copy(), self.blocks.copy()
        master[src], xi[src], gap0[src], law[src], blocks[src] = (new.master, new.xi, new.gap0,
                                                                  new.law, new.blocks)
        moved = (np.any(master != cont.master, axis=1) | np.any(xi != cont.xi, axis=1)
                 | (area != cont.area))
        # a candidate left as it was (partly over its face, within reach) is checked again only
        # once it slides further out
        stay = cand & ~moved
        self.outside0[stay] = np.maximum(self.outside0[stay], out[stay])
        if not moved.any():
            return 0
        self.outside0[moved] = 0.0
        self.apply(master, xi, gap0, law, area, blocks)
        return int(moved.sum())

    def apply(self, master, xi, gap0, law, area, blocks):
        """Install a contact set of the same points (arrays as in :class:`ContactSet`): the
        dissipation of points going off or coming back, then ``sim._contacts_changed``."""
        cont = self.sim.cont
        off = (area == 0.0) & (cont.area > 0.0)
        back = (area > 0.0) & (cont.area == 0.0)
        for k, col in enumerate((JS_DISS, JS_DISSF)):
            self.diss_off[k] += (cont.s_old[off, col] @ self.area0[off]
                                 - cont.s_old[back, col] @ self.area0[back])
        self.diss_off[0] += cont.psi[off].sum()
        cont.master[:], cont.xi[:], cont.gap0[:], cont.law[:], cont.area[:] = (master, xi, gap0,
                                                                              law, area)
        self.blocks[:] = blocks
        self.changed = True
        self.sim._contacts_changed()

    def state(self):
        """Arrays for a checkpoint (restored by :meth:`restore`)."""
        c = self.sim.cont
        return {"contacts/master": c.master, "contacts/xi": c.xi, "contacts/gap0": c.gap0,
                "contacts/law": c.law, "contacts/area": c.area, "contacts/blocks": self.blocks,
                "contacts/outside0": self.outside0, "contacts/diss_off": self.diss_off}

    def restore(self, arrays):
        """Install the set of a checkpoint written by :meth:`state` (if it holds one)."""
        if "contacts/master" not in arrays or not np.asarray(arrays["contacts/master"]).size:
            return
        a = {k.split("/")[1]: np.asarray(v) for k, v in arrays.items() if k.startswith("contacts/")}
        c = self.sim.cont
        same = (np.array_equal(a["master"], c.master) and np.array_equal(a["xi"], c.xi)
                and np.array_equal(a["gap0"], c.gap0) and np.array_equal(a["area"], c.area))
        self.outside0[:] = a["outside0"]
        if not same:
            self.apply(a["master"], a["xi"], a["gap0"], a["law"], a["area"], a["blocks"])
        self.diss_off[:] = a["diss_off"]
