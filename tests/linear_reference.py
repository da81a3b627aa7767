"""Independent linear reference for the verification tests: direct sparse solve of K u = f.

K is assembled here in plain numpy/scipy from the element matrices of ``kernels.hex8.hex_stiffness``
(tested on its own against a numpy reference in test_hex8.py) and from the linear stiffness of the
contact springs written out from the force convention of ``kernels/contact_forces.py``: a spring
with frame rows [n, t1, t2] (reference geometry), slave weight +1 and master weights -N_a, gives
``K_c = area * B^T diag(knn, kss, kss) B`` with ``B = frame @ [I, -N_0 I, .., -N_3 I]`` (3, 15).
Supports clamp DOFs; rigid points tie nodes by the linearised map
``u_i = u_p + theta_p x (X_i - X_p)``. A spring marked compressed takes the joint law's
compression penalty ``kc_pen`` as its normal stiffness instead of ``knn`` (kernels/joint_law.py).
"""
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from dr_masonry.kernels.contact_frame import contact_frame
from dr_masonry.kernels.hex8 import hex_geometry, hex_stiffness


def hex_matrix(model):
    """Global stiffness (3 n, 3 n) of the hexahedra of the non-fixed blocks, N/m (CSR)."""
    X, conn = model.nodes, model.elements
    dN, _, wdet, _ = hex_geometry(X, conn)
    mats = model.materials
    emat = model.block_material[model.element_block]
    rows, cols, vals = [], [], []
    ke = np.empty((24, 24))
    for e in np.nonzero(~model.block_fixed[model.element_block])[0]:
        m = mats[emat[e]]
        hex_stiffness(dN[e], wdet[e], m.E, m.nu, ke)
        dof = (3 * conn[e][:, None] + np.arange(3)[None, :]).ravel()
        rows.append(np.repeat(dof, 24))
        cols.append(np.tile(dof, 24))
        vals.append(ke.ravel().copy())
    n = 3 * model.n_nodes
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(n, n))


def contact_normals(model):
    """Unit normals (n_contacts, 3) of the contact springs at the reference state."""
    c, X = model.contacts, model.nodes
    xm, frame = np.empty(3), np.empty((3, 3))
    out = np.empty((c.n, 3))
    for q in range(c.n):
        contact_frame(np.ascontiguousarray(X[c.master[q]]), c.xi[q][0], c.xi[q][1], xm, frame)
        out[q] = frame[0]
    return out


def contact_matrix(model, compressed=None):
    """Global stiffness (3 n, 3 n) of the contact springs linearised at the reference state, N/m;
    ``compressed``: (n_contacts,) bool, the springs whose normal stiffness is ``kc_pen``."""
    c = model.contacts
    X = model.nodes
    laws = model.joint_laws
    rows, cols, vals = [], [], []
    xm = np.empty(3)
    frame = np.empty((3, 3))
    for q in range(c.n):
        r, s = c.xi[q]
        contact_frame(np.ascontiguousarray(X[c.master[q]]), r, s, xm, frame)
        shp = 0.25 * np.array([(1 - r) * (1 - s), (1 + r) * (1 - s), (1 + r) * (1 + s),
                               (1 - r) * (1 + s)])
        w = np.concatenate([[1.0], -shp])
        B = np.einsum("a,ij->iaj", w, frame).reshape(3, 15)
        law = laws[c.law[q]]
        kn = law.kc_pen if compressed is not None and compressed[q] else law.knn
        kq = c.area[q] * B.T @ np.diag([kn, law.kss, law.kss]) @ B
        nodes = np.concatenate([[c.slave[q]], c.master[q]])
        dof = (3 * nodes[:, None] + np.arange(3)[None, :]).ravel()
        rows.append(np.repeat(dof, 15))
        cols.append(np.tile(dof, 15))
        vals.append(kq.ravel())
    n = 3 * model.n_nodes
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(n, n))


def solve(model, fixed, f, rigid=(), compressed=None):
    """Linear displacements of the model under nodal forces.

    Parameters
    ----------
    model : Model with detected contacts (``model.contacts``).
    fixed : (n, 3) bool
        clamped node DOFs.
    f : (n, 3) float64, N
        nodal forces.
    rigid : sequence of (nodes (m,) int, position (3,) m, force (6,) N / N m)
        rigid points: tied nodes, reference position and generalised force on their 6 DOFs.
    compressed : (n_contacts,) bool or None
        springs in compression (normal stiffness ``kc_pen``); None: none.

    Returns
    -------
    U : (n, 3) m, nodal displacements; Q : (len(rigid), 6) rigid-point displacements/rotations.
    """
    n = model.n_nodes
    K = hex_matrix(model) + contact_matrix(model, compressed)
    tied = np.zeros(n, dtype=bool)
    for nodes, _, _ in rigid:
        tied[nodes] = True
    own = (~fixed) & (~tied[:, None])
    free_dof = np.nonzero(own.ravel())[0]
    nf = free_dof.size
    # T maps reduced unknowns [free node DOFs, 6 per rigid point] to the 3 n node DOFs
    ti = list(free_dof)
    tj = list(range(nf))
    tv = [1.0] * nf
    X = model.nodes
    for p, (nodes, pos, force) in enumerate(rigid):
        base = nf + 6 * p
        for i in nodes:
            a = X[i] - pos
            # u_i = u_p + theta x a
            lin = {0: [(0, 1.0), (4, a[2]), (5, -a[1])],
                   1: [(1, 1.0), (5, a[0]), (3, -a[2])],
                   2: [(2, 1.0), (3, a[1]), (4, -a[0])]}
            for k, terms in lin.items():
                for j, v in terms:
                    ti.append(3 * i + k)
                    tj.append(base + j)
                    tv.append(v)
    nq = nf + 6 * len(rigid)
    T = sp.csr_matrix((tv, (ti, tj)), shape=(3 * n, nq))
    b = T.T @ f.ravel()  # nodal forces on tied nodes act through T as well
    for p, (_, _, force) in enumerate(rigid):
        b[nf + 6 * p:nf + 6 * p + 6] += np.asarray(force, dtype=np.float64)
    q = spla.spsolve((T.T @ K @ T).tocsc(), b)
    U = (T @ q).reshape(n, 3)
    return U, q[nf:].reshape(-1, 6)


def rigid_point_stiffness(model, fixed, nodes, position, dof, held=(), compressed=None):
    """Stiffness (N/m or N m/rad) of a rigid point's DOF ``dof`` (0..5: x, y, z, rx, ry, rz)
    with the DOFs ``held`` at zero and the others free: the inverse of the flexibility matrix
    of [dof, *held] (one linear solve per unit generalised force), its first diagonal term."""
    which = [dof, *held]
    flex = np.empty((len(which), len(which)))
    zero = np.zeros((model.n_nodes, 3))
    for j, k in enumerate(which):
        force = np.zeros(6)
        force[k] = 1.0
        _, Q = solve(model, fixed, zero, [(nodes, position, force)], compressed)
        flex[:, j] = Q[0, which]
    return np.linalg.inv(flex)[0, 0]
