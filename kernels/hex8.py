"""8-node hexahedron: internal forces (total-Lagrangian reference and the corotational elements
of a run).

Geometry, shape functions, lumped mass and the stiffness bound are in
:mod:`~dr_masonry.kernels.hex8_geometry`, the corotational rotation and tables in
:mod:`~dr_masonry.kernels.corotational`; their names are imported here too, so that callers can
keep importing every hexahedron name from this module.

Conventions
-----------
* Corner order is VTK's (``CORNERS[a]`` = natural coordinates of corner a; ``dr_masonry.model``
  takes it from here as ``HEX_NATURAL``).
* 2x2x2 Gauss rule, unit weights; Gauss point g sits at ``CORNERS[g] / sqrt(3)``.
* ``dN`` (nt, 8, 8, 3) 1/m: dN_a/dX_i in the reference configuration, indexed
  [table, gauss point, node, direction]; element e reads table ``geo[e]``. Elements equal up to
  a translation (the bricks of a wall) share one table, found by :func:`hex_geometry_shared`;
  :func:`hex_geometry` gives one table per element (``geo = arange(ne)``, for tests and
  reference solutions).
  ``wdet`` (ne, 8) m^3: Gauss weight x det(dX/dxi), per element.
* Runs compute every element as a corotational hexahedron (:func:`corot_local`): linear in the
  frame of the rotation of its mean deformation gradient, K d for an elastic material
  (:func:`corot_global`), the Gauss-point update of the linear local strains for a damaging one
  (:func:`corot_damaging`); tables by :func:`corot_tables`.
* :func:`gauss_forces` (the tests' and benchmarks' reference, never a run's) computes an element
  as total-Lagrangian: F = I + sum_a u_a (x) dN_a,
  Green-Lagrange strain E = (H + H^T + H^T H) / 2 with H = F - I (no cancellation at small
  strain), Voigt order [xx, yy, zz, yz, xz, xy] with engineering shears; the material returns
  the second Piola-Kirchhoff stress S (Pa) in the same order; nodal internal force
  f_a = sum_g wdet_g F S dN_a (N).
"""
import numpy as np

from .config import ijit, jit, pjit, prange
from .corotational import corot_global, corot_local, corot_tables, polar_rotation  # noqa: F401
from .hex8_geometry import (CHUNK, CORNERS, HexMeshError, displacement_gradient,  # noqa: F401
                            hex_geometry, hex_geometry_shared,
                            hex_stiffness, inverted_element, lumped_mass, stiffness_rowsum,
                            trilinear_shape)
from .plastic_damage import (MP_ELASTIC, MP_SBC0, MP_SBT0, MS_EPSP, NMS, elastic_stress,
                             gp_update, surely_elastic, trial_stress)


# ---------------------------------------------------------------------------- internal forces
@ijit
def hex_gauss_strain(ue, dng, F, eps):
    """Deformation gradient ``F`` (3, 3) and Green-Lagrange strain ``eps`` (6,) at one Gauss point.

    ``ue`` (8, 3) m nodal displacements, ``dng`` (8, 3) 1/m reference derivatives.
    ``eps`` in Voigt order [xx, yy, zz, yz, xz, xy], engineering shears.
    """
    h00, h01, h02, h10, h11, h12, h20, h21, h22 = displacement_gradient(ue, dng, 0.0, 0.0, 0.0)
    eps[0] = h00 + 0.5 * (h00 * h00 + h10 * h10 + h20 * h20)
    eps[1] = h11 + 0.5 * (h01 * h01 + h11 * h11 + h21 * h21)
    eps[2] = h22 + 0.5 * (h02 * h02 + h12 * h12 + h22 * h22)
    eps[3] = h12 + h21 + h01 * h02 + h11 * h12 + h21 * h22
    eps[4] = h02 + h20 + h00 * h02 + h10 * h12 + h20 * h22
    eps[5] = h01 + h10 + h00 * h01 + h10 * h11 + h20 * h21
    F[0, 0], F[0, 1], F[0, 2] = 1.0 + h00, h01, h02
    F[1, 0], F[1, 1], F[1, 2] = h10, 1.0 + h11, h12
    F[2, 0], F[2, 1], F[2, 2] = h20, h21, 1.0 + h22


@ijit
def hex_add_gauss_force(F, sig, dng, w, fe):
    """Add the Gauss point's contribution w F S dN_a to the element forces ``fe`` (8, 3) N.

    ``F`` (3, 3) deformation gradient, ``sig`` (6,) Pa second Piola-Kirchhoff stress (Voigt),
    ``dng`` (8, 3) 1/m, ``w`` m^3 weight x det J.
    """
    s00, s11, s22, s12, s02, s01 = sig[0], sig[1], sig[2], sig[3], sig[4], sig[5]
    for i in range(3):
        f0, f1, f2 = w * F[i, 0], w * F[i, 1], w * F[i, 2]
        p0 = f0 * s00 + f1 * s01 + f2 * s02
        p1 = f0 * s01 + f1 * s11 + f2 * s12
        p2 = f0 * s02 + f1 * s12 + f2 * s22
        for a in range(8):
            fe[a, i] += p0 * dng[a, 0] + p1 * dng[a, 1] + p2 * dng[a, 2]


@ijit
def gauss_point_update(p, he, eps, s_old_e, s_new_e, g, sig):
    """The material update of Gauss point ``g`` of an element (``gp_update``: stress ``sig`` (6,)
    Pa and trial state ``s_new_e[g]`` written; states (8, NMS)) and twice its stored energy
    density sigma . (eps - eps_p), J/m^3."""
    gp_update(p, he, eps, s_old_e[g], s_new_e[g], sig)
    acc = 0.0
    for m in range(6):
        acc += sig[m] * (eps[m] - s_new_e[g, MS_EPSP + m])
    return acc


@ijit
def gather_element(U, conn, e, ue, fe):
    """Displacements ``ue`` (8, 3) m of element ``e``'s nodes from ``U``; its forces ``fe`` (8, 3)
    zeroed."""
    for a in range(8):
        n = conn[e, a]
        for i in range(3):
            ue[a, i] = U[n, i]
            fe[a, i] = 0.0


@ijit
def hex_chunk(lo, hi, U, conn, active, dN, geo, wdet, h, elem_mat, params, s_old, s_new, pristine,
              dirty, ke, kbt, kxo, kdn, kid, f_elem, energy):
    """Elements ``active[lo:hi]`` of the force kernel (one parallel task, its own scratch), each a
    corotational hexahedron (table ``kid[e]`` of :func:`corot_tables`; an element without one
    gets NaN forces, which the run's guards stop on)."""
    ue = np.empty((8, 3))
    F = np.empty((3, 3))
    eps = np.empty(6)
    sig = np.empty(6)
    # local displacements, rotations and table of each slot of the task, and the Gauss-point
    # strains of the damaging ones
    ns = hi - lo
    dl = np.empty((ns, 24))
    fl = np.empty((ns, 24))
    rot = np.empty((ns, 3, 3))
    slot = np.full(ns, -1, dtype=np.int64)
    strains = np.empty((ns, 48))
    for k in range(lo, hi):
        e = active[k]
        gather_element(U, conn, e, ue, f_elem[e])
        t = kid[e]
        if t >= 0 and corot_local(ue, kxo[t], kdn[t], rot[k - lo], dl[k - lo]) > 0.0:
            slot[k - lo] = t   # K d (and the damaging ones' strains) below
        else:   # no table, or inverted: NaN for the run's guards
            f_elem[e, :, :] = np.nan
            energy[e] = np.nan
    j = 0
    while j < ns:   # K d of each run of slots with one table: one matrix product (BLAS)
        t = slot[j]
        j1 = j + 1
        while j1 < ns and slot[j1] == t:
            j1 += 1
        if t >= 0:
            np.dot(dl[j:j1], ke[t], fl[j:j1])   # K symmetric: (K d)^T = d^T K
            p = params[elem_mat[active[lo + j]]]   # a table's elements share one material
            if p[MP_ELASTIC] == 1.0:
                for jj in range(j, j1):
                    e = active[lo + jj]
                    energy[e] = corot_global(rot[jj], dl[jj], fl[jj], f_elem[e])
            else:
                np.dot(dl[j:j1], kbt[t], strains[j:j1])   # the 8 points' strains B_g d
                for jj in range(j, j1):
                    e = active[lo + jj]
                    fast = pristine[e] != 0   # virgin committed state
                    if fast and corot_surely_elastic(p, strains[jj]):   # K d, no state
                        energy[e] = corot_global(rot[jj], dl[jj], fl[jj], f_elem[e])
                        if dirty[e] != 0:   # trial state = committed state again
                            s_new[e] = s_old[e]
                            dirty[e] = 0
                    else:
                        energy[e] = corot_damaging(p, h[e], s_old[e], s_new[e], dN[geo[e]],
                                                   wdet[e], strains[jj], rot[jj], f_elem[e], F,
                                                   eps, sig, ue)
                        if fast:
                            dirty[e] = 1
        j = j1


@pjit
def gauss_forces(U, conn, active, dN, geo, wdet, h, elem_mat, params, s_old, s_new, pristine,
                 dirty, f_elem, energy):
    """Every element of ``active`` as a total-Lagrangian hexahedron at its Gauss points: the
    reference that the corotational element of a run is tested and benchmarked against (arguments
    those of :func:`.forces.hex_forces` without tables; runs never call it, so it is compiled
    apart from their force kernel: 7 s of their cold start)."""
    na = active.shape[0]
    for t in prange((na + CHUNK - 1) // CHUNK):   # tasks of CHUNK elements, scratch per task
        ue = np.empty((8, 3))
        F = np.empty((3, 3))
        eps = np.empty(6)
        sig = np.empty(6)
        for k in range(t * CHUNK, min(na, (t + 1) * CHUNK)):
            e = active[k]
            fe = f_elem[e]
            gather_element(U, conn, e, ue, fe)
            p = params[elem_mat[e]]
            plastic = p[MP_ELASTIC] != 1.0
            fast = plastic and pristine[e] != 0   # virgin state: no state to read while elastic
            dne = dN[geo[e]]
            en = 0.0
            for g in range(8):
                dng = dne[g]
                hex_gauss_strain(ue, dng, F, eps)
                w = wdet[e, g]
                acc = 0.0
                if fast:   # the committed state is the virgin one: the material's strengths
                    i1, q, d0, d1, d2, d3, d4, d5 = trial_stress(p, eps[0], eps[1], eps[2], eps[3],
                                                                 eps[4], eps[5])
                    if surely_elastic(p, i1, q, p[MP_SBT0], p[MP_SBC0]):
                        m0 = i1 / 3.0
                        sig[0] = m0 + d0
                        sig[1] = m0 + d1
                        sig[2] = m0 + d2
                        sig[3] = d3
                        sig[4] = d4
                        sig[5] = d5
                    else:   # the element leaves its virgin state: the full update from here on
                        fast = False
                        for gg in range(g):
                            for m in range(NMS):
                                s_new[e, gg, m] = s_old[e, gg, m]
                        dirty[e] = 1
                if not plastic:
                    elastic_stress(p, eps, sig)
                if plastic and not fast:
                    acc = gauss_point_update(p, h[e], eps, s_old[e], s_new[e], g, sig)
                else:   # elastic stress from the total strain (no plastic strain)
                    for m in range(6):
                        acc += sig[m] * eps[m]
                hex_add_gauss_force(F, sig, dng, w, fe)
                en += 0.5 * w * acc
            if fast and dirty[e] != 0:   # trial state = committed state again
                for g in range(8):
                    for m in range(NMS):
                        s_new[e, g, m] = s_old[e, g, m]
                dirty[e] = 0
            energy[e] = en


@ijit
def corot_surely_elastic(p, strains):
    """Whether all 8 Gauss points of a virgin corotational element of material ``p`` are surely
    elastic at local strains ``strains`` (48,) (Voigt, engineering shears, point g at 6 g)."""
    for g in range(8):
        o = 6 * g
        i1, q, _, _, _, _, _, _ = trial_stress(p, strains[o], strains[o + 1], strains[o + 2],
                                               strains[o + 3], strains[o + 4], strains[o + 5])
        if not surely_elastic(p, i1, q, p[MP_SBT0], p[MP_SBC0]):
            return False
    return True


# a call, not inlined: inlined it added 2.5 s to the cold compile to save the call's 80 ns of a
# damaged element's 1,000 in its elastic range (6,600 in plastic flow), within the
# noise of whole runs
@jit
def corot_damaging(p, he, s_old_e, s_new_e, dne, we, strains, R, fe, eye, eps, sig, floc):
    """Forces ``fe`` (8, 3) N of one corotational element of a damaging material.

    In the element's rotated frame (:func:`corot_local`: rotation ``R``) the strain of Gauss
    point g is linear, ``strains[6 g:6 g + 6]`` = B_g d (Voigt, engineering shears); the
    material updates it (``gp_update``: committed states ``s_old_e`` (8, NMS), trial
    ``s_new_e``, written) and the local forces sum_g w_g B_g^T sigma_g (``dne`` (8, 8, 3) 1/m,
    ``we`` (8,) m^3) turn back with ``R``. Scratch: ``eye`` (3, 3) (set to I here), ``eps``,
    ``sig`` (6,), ``floc`` (8, 3). Returns the stored energy, J.
    """
    for i in range(3):
        for k in range(3):
            eye[i, k] = 1.0 if i == k else 0.0
    floc[:, :] = 0.0
    en = 0.0
    for g in range(8):
        for m in range(6):
            eps[m] = strains[6 * g + m]
        en += 0.5 * we[g] * gauss_point_update(p, he, eps, s_old_e, s_new_e, g, sig)
        hex_add_gauss_force(eye, sig, dne[g], we[g], floc)
    for a in range(8):
        g0, g1, g2 = floc[a, 0], floc[a, 1], floc[a, 2]
        for i in range(3):
            fe[a, i] = R[i, 0] * g0 + R[i, 1] * g1 + R[i, 2] * g2
    return en


def pristine_elements(s_old, s_virgin, h, h_max):
    """Elements whose committed Gauss-point states are all virgin: (ne,) uint8 for
    :func:`.forces.hex_forces`.

    ``s_old`` (ne, 8, NMS) committed states, ``s_virgin`` (ne, NMS) each element's material's
    initial state, ``h`` (ne,) m element lengths and ``h_max`` (ne,) m their materials' largest
    length (an element outside (0, h_max] is not pristine: its update flags the clamp).
    """
    virgin = np.all(s_old == s_virgin[:, None, :], axis=(1, 2))
    return (virgin & (h > 0.0) & (h <= h_max)).astype(np.uint8)
