"""The internal forces of one iteration: hexahedra and contact points in one parallel region.

The arrays of the two sets travel in named tuples (built by ``dr_masonry.solver``; their fields
documented at :func:`hex_forces` and :func:`contact_forces`): ``Mesh`` (hexahedra; ``ptr``,
``rows`` the node map of their force rows, :func:`~.assembly.node_row_map`) and ``Cont``
(contact points; ``ptr``, ``rows`` likewise). :func:`element_and_contact_forces` is the one force
kernel; :func:`hex_forces` (with corotational tables) and :func:`contact_forces` call it with the
other set empty, so that tests and benchmarks run the compiled code of a run (and compile nothing
more). Without tables :func:`hex_forces` calls :func:`.hex8.gauss_forces`, the total-Lagrangian
reference element, compiled apart.
"""
from collections import namedtuple

import numpy as np

from .config import pjit, prange
from .contact_forces import CHUNK as CONTACT_CHUNK
from .contact_forces import contact_chunk
from .hex8 import CHUNK as HEX_CHUNK
from .hex8 import gauss_forces, hex_chunk
from .joint_law import NJP, NJS
from .plastic_damage import NMS

Mesh = namedtuple("Mesh", "conn active dN geo wdet h emat mparams s_old s_new pristine dirty ke "
                         "kbt kxo kdn kid fbuf energy ptr rows")
Cont = namedtuple("Cont", "slave master xi area law lparams gap0 s_old s_new gaps trac fbuf psi ptr rows")


@pjit
def element_and_contact_forces(X, U, mesh, cont):
    """``hex_forces`` of ``mesh.active`` and ``contact_forces`` of every contact point as the
    tasks of one parallel region (one wake-up of the threads instead of two); writes
    ``mesh.fbuf``, ``mesh.energy`` and ``cont``'s outputs. ``X``, ``U``: (n_nodes, 3), m.

    Numba splits a ``prange`` into one block per thread, so the hexahedron tasks (about 7 x a
    contact task in the elastic range) are spread evenly over the range to balance the blocks."""
    na = mesh.active.shape[0]
    nc = cont.slave.shape[0]
    nh = (na + HEX_CHUNK - 1) // HEX_CHUNK
    nt = nh + (nc + CONTACT_CHUNK - 1) // CONTACT_CHUNK
    for t in prange(nt):
        j = (t + 1) * nh // nt   # hexahedron tasks among the first t + 1
        if j > t * nh // nt:
            hc = j - 1
            hex_chunk(hc * HEX_CHUNK, min(na, (hc + 1) * HEX_CHUNK), U, mesh.conn, mesh.active,
                      mesh.dN, mesh.geo, mesh.wdet, mesh.h, mesh.emat, mesh.mparams,
                      mesh.s_old, mesh.s_new, mesh.pristine, mesh.dirty, mesh.ke, mesh.kbt,
                      mesh.kxo, mesh.kdn, mesh.kid, mesh.fbuf, mesh.energy)
        else:
            c = t - j
            contact_chunk(c * CONTACT_CHUNK, min(nc, (c + 1) * CONTACT_CHUNK), X, U,
                          cont.slave, cont.master, cont.xi, cont.area, cont.law, cont.lparams,
                          cont.gap0, cont.s_old, cont.s_new, cont.gaps, cont.trac, cont.fbuf,
                          cont.psi)


def _none(*shape, dtype=np.float64):
    """Zeros of ``shape`` (a field of an empty set: only its Numba type matters)."""
    return np.zeros(shape, dtype=dtype)


#: an empty contact set and an empty element set (the other argument of the force kernel)
NO_CONTACTS = Cont(_none(0, dtype=np.int64), _none(0, 4, dtype=np.int64), _none(0, 2), _none(0),
                   _none(0, dtype=np.int64), _none(1, NJP), _none(0, 3), _none(0, NJS),
                   _none(0, NJS), _none(0, 3), _none(0, 3), _none(0, 3), _none(0),
                   _none(1, dtype=np.int64), _none(0, dtype=np.int64))
NO_ELEMENTS = Mesh(_none(0, 8, dtype=np.int64), _none(0, dtype=np.int64), _none(0, 8, 8, 3),
                   _none(0, dtype=np.int64), _none(0, 8), _none(0), _none(0, dtype=np.int64),
                   _none(1, 1), _none(0, 8, NMS), _none(0, 8, NMS), _none(0, dtype=np.uint8),
                   _none(0, dtype=np.uint8), _none(0, 24, 24), _none(0, 24, 48), _none(0, 8, 3),
                   _none(0, 8, 3), _none(0, dtype=np.int64), _none(0, 8, 3), _none(0),
                   _none(1, dtype=np.int64), _none(0, dtype=np.int64))


def hex_only_args(U, conn, active, dN, geo, wdet, h, elem_mat, params, s_old, s_new, pristine,
                  dirty, f_elem, energy, corot):
    """Arguments of :func:`element_and_contact_forces` for :func:`hex_forces` with tables ``corot``
    (same parameters): (X, U, Mesh of these arrays without a node map, NO_CONTACTS). The reference
    coordinates are read by contact points only: U stands in for them."""
    return U, U, Mesh(conn, active, dN, geo, wdet, h, elem_mat, params, s_old, s_new, pristine,
                      dirty, *corot, f_elem, energy, NO_CONTACTS.ptr, NO_CONTACTS.rows), NO_CONTACTS


def contact_only_args(X, U, slave, master, xi, area, law, lparams, gap0, s_old, s_new, gaps, trac,
                      fbuf, psi):
    """Arguments of :func:`element_and_contact_forces` for :func:`contact_forces` (same
    parameters): (X, U, NO_ELEMENTS, Cont of these arrays without a node map)."""
    return X, U, NO_ELEMENTS, Cont(slave, master, xi, area, law, lparams, gap0, s_old, s_new, gaps,
                                   trac, fbuf, psi, NO_CONTACTS.ptr, NO_CONTACTS.rows)


def hex_forces(U, conn, active, dN, geo, wdet, h, elem_mat, params, s_old, s_new, pristine,
               dirty, f_elem, energy, corot=None):
    """Internal forces and stored elastic energy of the ``active`` elements (parallel, race-free).

    Parameters
    ----------
    U : (n_nodes, 3) float64, m
        nodal displacements.
    conn : (ne, 8) int64
        node ids per element.
    active : (na,) int64
        element ids to compute; other elements are untouched.
    dN, geo, wdet, h
        from :func:`.hex8.hex_geometry_shared` or :func:`.hex8.hex_geometry`: element e reads table
        ``dN[geo[e]]``.
    elem_mat : (ne,) int64
        row of ``params`` for each element.
    params : (nmat, NMP) float64
        ``PlasticDamage.params_array()`` rows; a row with ``p[MP_ELASTIC] == 1`` takes the
        elastic fast path (``elastic_stress``, no state read or written).
    s_old, s_new : (ne, 8, NMS) float64
        committed (read) and trial (written by ``gp_update``; not for elastic materials; its
        ``MS_DL``, the previous return's multiplier, read first as the next one's guess)
        Gauss-point states.
    pristine : (ne,) uint8
        1 where the committed state of every Gauss point is the material's virgin state
        (:func:`.hex8.pristine_elements`): while all its points stay surely elastic the element takes
        the elastic path of its material without reading or writing the state (the trial state
        is then the committed one; bit for bit the forces of ``gp_update``).
    dirty : (ne,) uint8
        read and written: 1 where ``s_new`` may differ from ``s_old`` (a pristine element that
        went through ``gp_update``); such an element is reset to ``s_old`` when it is back in
        its elastic range. Zero wherever ``s_new`` equals ``s_old`` (after a commit).
    f_elem : (ne, 8, 3) float64, N
        element internal forces, written.
    energy : (ne,) float64, J
        stored elastic energy sum_g wdet 0.5 S : (E - E_p), written (E_p = 0 for a
        material with ``p[MP_ELASTIC] == 1``; on the corotational path the local strains for
        E and the stresses for S, d.K d / 2 where the element is elastic).
    corot : tuple, optional
        ``(ke, kbt, kxo, kdn, kid)`` of :func:`.hex8.corot_tables`, a table (``kid >= 0``) for
        every active element: each takes the corotational path of a run
        (:func:`.hex8.corot_local`), linear in the element's rotated frame, K d for an elastic
        material, the Gauss-point update of the linear local strains for a damaging one
        (:func:`.hex8.corot_damaging`). None: every element at its Gauss points, total
        Lagrangian (:func:`.hex8.gauss_forces`, the reference element).

    Raises
    ------
    ValueError
        if ``corot`` gives an active element no table (it would get NaN forces).
    """
    if corot is None:
        gauss_forces(U, conn, active, dN, geo, wdet, h, elem_mat, params, s_old, s_new, pristine,
                     dirty, f_elem, energy)
        return
    missing = active[corot[4][active] < 0]
    if missing.size:
        raise ValueError(f"hex_forces: active element {missing[0]} has no corotational table "
                         f"(kid < 0; {missing.size} such elements): give every active element "
                         "one, or pass corot=None")
    element_and_contact_forces(*hex_only_args(U, conn, active, dN, geo, wdet, h, elem_mat, params,
                                              s_old, s_new, pristine, dirty, f_elem, energy,
                                              corot))


def contact_forces(X, U, slave, master, xi, area, law, lparams, gap0, s_old, s_new, gaps, trac,
                   fbuf, psi):
    """Evaluate every contact point at current coordinates ``X + U`` (n_nodes, 3), m.

    Parameters
    ----------
    X, U : (n_nodes, 3) reference coordinates and displacements, m.
    slave (nc,), master (nc, 4), xi (nc, 2), area (nc,) m^2, law (nc,), lparams (n_laws, NJP),
    gap0 (nc, 3) m : the contact set (docs/internals.md).
    s_old, s_new : (nc, NJS) committed and updated joint histories.
    gaps, trac : (nc, 3) written: local gap [u, d1, d2] (m) and tractions [sigma, tau1, tau2] (Pa).
    fbuf : (nc * 5, 3) written: internal force on the slave (row 5c) and masters (5c + 1..4), N.
    psi : (nc,) written: stored energy of each point, J.
    """
    element_and_contact_forces(*contact_only_args(X, U, slave, master, xi, area, law, lparams,
                                                  gap0, s_old, s_new, gaps, trac, fbuf, psi))
