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
its point gets area 0 (no force, no stiffness) until a face takes it again, and comes back as a
fresh dry contact (:meth:`Sliding._seat`): nothing it did while off carries into its forces or
its dissipation. A node that lies behind the face that takes it back (it came round the face's
edge: a crushed corner hanging over a brick's edge and moved back over it) is seated where it is,
``sunk`` below the face: its penetration so far is accepted and only a further one resisted, and
the seat rises with the node whenever it moves out, until it is back at the face (the
penetration-ignoring seat of explicit contact codes). A node further behind than ``SINK`` is on
the far side of the brick, not in it: its point stays off. Nothing runs while no
node leaves its quad (one projection of the slave nodes per increment); the masses, the node
maps of the gather and the coarse operator are refreshed only when the set changes.

The number of points stays fixed, so every contact array and frame field keeps its shape; frames
written after the first change carry the contact set valid for them (docs/file_format.md).
"""
from __future__ import annotations

import numpy as np

from .contact_search import ContactSet, element_edge, local_gaps, project_bilinear, redetect
from .kernels.joint_law import JS_D, JS_DISS, JS_DISSF, JS_DP1, JS_DP2, JS_G1, JS_G2, JS_GU
from .results import check_stored

#: how far (natural coordinates beyond +-1: 0.1 is 5 % of the quad's edge) a slave node must
#: have slid out of its quad before its point is re-paired. Nodes that start on the edge between
#: two quads (most of them) would otherwise switch back and forth at every micro-slip, and each
#: switch moves forces between the quads' nodes: on the S6 wall five such switches at its peak
#: sent the post-peak path elsewhere at three times the iterations (BENCHMARKS.md, "Finite-sliding check per increment")
SWITCH = 0.1

#: how far (fraction of the largest element edge of its block) a node off the surface may lie
#: behind a face that takes its point back and still be seated at the face. 1e-3 of a 50 mm
#: element is 50 um: a penetration at 37 MPa on the walls' penalty (7.5e11 Pa/m). A node further
#: behind went round the face's edge (a sagging, crushed corner that slid off a brick and comes
#: back under its top face): seated at the face, the penalty would throw it out in one increment
#: (the S4 double-clamped cyclic run had two such nodes 8 mm behind, -6 GPa, thrown 0.17 m), so it
#: is seated where it is, sunk below the face (:meth:`Sliding._rise` lifts the seat)
BEHIND = 1e-3

#: how far (fraction of the same edge) behind a face a node may lie to be seated sunk in it; a
#: node further behind is nearer the brick's other faces than this one: its point stays off
SINK = 0.5


class Sliding:
    """Re-pairing state of a :class:`~dr_masonry.solver.Simulation`'s contact set (after build;
    the simulation makes one only for a model with contacts).

    Attributes
    ----------
    area0 : (nc,) m^2 tributary areas as detected (``cont.area`` is 0 where a point is off).
    u_ref : (nc,) m normal offset of every point as detected (``gap0[:, 0]``): the seat of a
        point a face takes back.
    behind_tol : (nc,) m how far behind a face a node may be to be seated at the face.
    sink_tol : (nc,) m how far behind a face a node may be to be seated at all (sunk in it).
    sunk : (nc,) m how far the seat of each point lies behind its face (0: at the face).
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
        self.u_ref = c.gap0[:, 0].copy()
        edge = element_edge(sim.model)[c.blocks[:, 0]]
        self.behind_tol = BEHIND * edge
        self.sink_tol = SINK * edge
        self.sunk = np.zeros(c.n)
        self.blocks = c.blocks.copy()
        x = sim.model.nodes
        self.outside0 = self._outside(x)
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
        x = sim.dyn.X + sim.dyn.U
        self._rise(x)
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
        # points a face takes back: seated at the face, or sunk where the node is behind it,
        # less those whose node is on the far side of the brick (they stay off)
        back = np.flatnonzero((area > 0.0) & (cont.area == 0.0))
        g = local_gaps(x, cont.slave[back], master[back], xi[back])
        depth = self.u_ref[back] - g[:, 0]
        far = depth > self.sink_tol[back]
        b = back[far]
        area[b] = 0.0
        master[b], xi[b], gap0[b], law[b], blocks[b] = (cont.master[b], cont.xi[b], cont.gap0[b],
                                                        cont.law[b], self.blocks[b])
        back, g, depth = back[~far], g[~far], depth[~far]
        moved = (np.any(master != cont.master, axis=1) | np.any(xi != cont.xi, axis=1)
                 | (area != cont.area))
        # a candidate left as it was (partly over its face, within reach) is checked again only
        # once it slides further out
        stay = cand & ~moved
        self.outside0[stay] = np.maximum(self.outside0[stay], out[stay])
        if not moved.any():
            return 0
        self.outside0[moved] = 0.0
        self.sunk[area == 0.0] = 0.0
        if back.size:
            self.sunk[back] = np.where(depth > self.behind_tol[back], depth, 0.0)
            gap0[back] = self._seat(back, g)
        self.apply(master, xi, gap0, law, area, blocks)
        return int(moved.sum())

    def _seat(self, back, g):
        """Seat the points a face takes back (indices ``back``, (nb,)) on their new quads, where
        their geometric local gaps are ``g`` (nb, 3) m; installs their joint state and returns
        their ``gap0`` (nb, 3) m.

        While off, a point's gap was measured against the plane of the quad it left and its
        joint law went on committing: the distance slid while off sat in its tangential gap and,
        where the node went below that plane, a stuck slider held it as elastic slip under a
        penalty pressure nothing exerted (area 0). Carried over, that state was released in the
        first increment back as friction over the whole distance, at that pressure (4.9 kJ in
        one increment of the S4 double-clamped cyclic run, docs/validation.md). A point taken
        back is instead a fresh contact between faces that were never bonded: local gap
        [u, 0, 0], u its geometric distance to the new quad less its offset as detected, no
        elastic or plastic slip, damage 1 (no tension, no cohesion); its largest opening and
        slip and its dissipation so far stay. Its committed state holds that seat, so its first
        increment back books only what happens in it. A point ``sunk`` behind its face is seated
        that much lower: u = 0 where its node is."""
        cont = self.sim.cont
        seat = np.zeros_like(g)
        seat[:, 0] = g[:, 0] - (self.u_ref[back] - self.sunk[back])
        for s in (cont.s_old, cont.s_new):
            s[back, JS_D] = 1.0
            s[back, JS_DP1] = s[back, JS_DP2] = 0.0
            s[back, JS_GU], s[back, JS_G1], s[back, JS_G2] = seat.T
        return g - seat

    def _rise(self, x):
        """Lift the seat of every sunk point whose node has moved out of it (normal gap u > 0 at
        the committed coordinates ``x`` (n_nodes, 3) m) by u, at most back to the face. The
        point is a dry contact (damage 1) open by u, with neither traction nor stored energy: the
        lift changes neither, only where a later closing meets resistance."""
        s = np.flatnonzero(self.sunk > 0.0)
        if not s.size:
            return
        cont = self.sim.cont
        u = local_gaps(x, cont.slave[s], cont.master[s], cont.xi[s])[:, 0] - cont.gap0[s, 0]
        lift = np.minimum(np.maximum(u, 0.0), self.sunk[s])
        cont.gap0[s, 0] += lift
        self.sunk[s] -= lift
        for st in (cont.s_old, cont.s_new):
            st[s, JS_GU] -= lift

    def apply(self, master, xi, gap0, law, area, blocks):
        """Install a contact set of the same points (arrays as in :class:`ContactSet`): the
        dissipation of points going off or coming back, then ``solver.arrays.contacts_changed``."""
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
        from .solver.arrays import contacts_changed
        contacts_changed(self.sim)

    def state(self):
        """Arrays for a checkpoint (restored by :meth:`restore`)."""
        c = self.sim.cont
        return {"contacts/master": c.master, "contacts/xi": c.xi, "contacts/gap0": c.gap0,
                "contacts/law": c.law, "contacts/area": c.area, "contacts/blocks": self.blocks,
                "contacts/outside0": self.outside0, "contacts/diss_off": self.diss_off,
                "contacts/sunk": self.sunk}

    def _check(self, a):
        """Raise :class:`~dr_masonry.results.ResultsError` unless the checkpoint's contact arrays
        ``a`` (name -> array) have this set's shapes, finite values and valid indices
        (:func:`~dr_masonry.results.check_stored`)."""
        c, m = self.sim.cont, self.sim.model
        ref = {"master": (c.master, m.n_nodes), "xi": (c.xi, None), "gap0": (c.gap0, None),
               "area": (c.area, None), "law": (c.law, len(m.joint_laws)),
               "blocks": (self.blocks, m.n_blocks), "outside0": (self.outside0, None),
               "diss_off": (self.diss_off, None)}
        if "sunk" in a:   # checkpoints written before the sunk seats have none: all at the face
            ref["sunk"] = (self.sunk, None)
        for k, (arr, bound) in ref.items():
            check_stored(self.sim.output, f"contacts/{k}", a.get(k), arr.shape, bound)

    def restore(self, arrays):
        """Install the set of a checkpoint written by :meth:`state` (if it holds one)."""
        if "contacts/master" not in arrays or not np.asarray(arrays["contacts/master"]).size:
            return
        a = {k.split("/")[1]: np.asarray(v) for k, v in arrays.items() if k.startswith("contacts/")}
        c = self.sim.cont
        self._check(a)
        same = (np.array_equal(a["master"], c.master) and np.array_equal(a["xi"], c.xi)
                and np.array_equal(a["gap0"], c.gap0) and np.array_equal(a["area"], c.area))
        self.outside0[:] = a["outside0"]
        self.sunk[:] = a.get("sunk", 0.0)
        if not same:
            self.apply(a["master"], a["xi"], a["gap0"], a["law"], a["area"], a["blocks"])
        self.diss_off[:] = a["diss_off"]
