"""What one sparse direct solve of a scene's stiffness costs on this machine (BENCHMARKS.md, "The
cost of a direct solve"): the price per factorization that an implicit (Newton) solver of the same model would
pay, against the run time of the relaxation.

Builds scene ``scene`` (its ``args``, e.g. ``mesh=fine``) without running it and assembles the
stiffness of its initial, undamaged state over the free DOFs of its untied nodes: every active
hexahedron's corotational table ``ke`` (its reference frame is the global one before any
motion) and every contact point as an isotropic spring of the joint's normal stiffness ``knn``
x area coupling the slave node (weight 1) with its master quad's nodes (weights -N_a). The
reference points (rigid beams) and their tied nodes are left out, so the matrix is the model's
node-to-node sparsity with its true size. Then scipy's SuperLU (``splu``, the direct solver the
fixed packages hold) factorizes it with each column ordering of ``orderings`` and solves one
right-hand side: seconds per factorization and per solve, fill (nnz of L + U), residual. By
default in SuperLU's symmetric mode without pivoting (the matrix is symmetric positive definite;
so would a Newton tangent be with associated joints); ``pivoting=true`` factorizes it as a general
matrix, as an unsymmetric tangent (friction without dilatancy) needs.

``python benchmarks/direct_solve.py [scene=squat_wall args=mesh=fine orderings=MMD_AT_PLUS_A,COLAMD
pivoting=false]`` (about 20 s for the S5 fine wall; with pivoting and MMD_AT_PLUS_A about 2 min);
writes ``benchmarks/out/direct_solve.csv``.
"""
import time

import numpy as np

import common

DEFAULTS = dict(scene="squat_wall", args="mesh=fine", orderings="MMD_AT_PLUS_A,COLAMD",
                pivoting=False)


def stiffness(sim):
    """(K, free): the initial stiffness (CSC, N/m) over the free DOFs of untied nodes, and the
    (n, 3) mask of those DOFs."""
    import scipy.sparse as sp
    from dr_masonry.kernels.config import plain
    from dr_masonry.kernels.contact_frame import quad_shape
    from dr_masonry.kernels.joint_law import P_KNN
    m, c, d = sim.mesh, sim.cont, sim.dyn
    n = d.X.shape[0]
    act = m.active
    dofs = (3 * m.conn[act][:, :, None] + np.arange(3)).reshape(-1, 24)
    vals = [m.ke[m.kid[act]].reshape(-1)]
    rows = [np.repeat(dofs, 24, axis=1).ravel()]
    cols = [np.tile(dofs, (1, 24)).ravel()]
    shp = np.column_stack(plain(quad_shape)(c.xi[:, 0], c.xi[:, 1]))
    w = np.column_stack([np.ones(c.slave.size), -shp])                  # (nc, 5)
    nodes = np.column_stack([c.slave, c.master])                         # (nc, 5)
    k = c.lparams[c.law, P_KNN] * c.area                                 # (nc,) N/m
    kw = k[:, None, None] * w[:, :, None] * w[:, None, :]                # (nc, 5, 5)
    for j in range(3):
        nd = 3 * nodes + j
        vals.append(kw.reshape(-1))
        rows.append(np.repeat(nd, 5, axis=1).ravel())
        cols.append(np.tile(nd, (1, 5)).ravel())
    K = sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(3 * n, 3 * n)).tocsc()
    free = (d.free > 0) & (d.tied[:, None] < 0)
    idx = np.nonzero(free.ravel())[0]
    return K[idx][:, idx].tocsc(), free


def main(argv=None):
    params = common.start(DEFAULTS, __doc__, argv)
    import scipy.sparse.linalg as spla
    sim, _ = common.built_scene(params["scene"], params["args"], "direct_solve_run")
    sim.build()
    t = time.perf_counter()
    K, free = stiffness(sim)
    t_asm = time.perf_counter() - t
    b = np.random.default_rng(0).standard_normal(K.shape[0])
    out = []
    for spec in params["orderings"].split(","):
        t = time.perf_counter()
        if params["pivoting"]:
            lu = spla.splu(K, permc_spec=spec)
        else:
            lu = spla.splu(K, permc_spec=spec, diag_pivot_thresh=0.0,
                           options=dict(SymmetricMode=True))
        t_fac = time.perf_counter() - t
        t = time.perf_counter()
        x = lu.solve(b)
        t_sol = time.perf_counter() - t
        out.append(dict(scene=params["scene"], args=params["args"], nodes=int(free.shape[0]),
                        hexahedra=int(sim.mesh.active.size), contact_points=int(sim.cont.slave.size),
                        dofs=int(K.shape[0]), nnz_K=int(K.nnz), assembly_s=t_asm, ordering=spec,
                        pivoting=bool(params["pivoting"]),
                        factor_s=t_fac, nnz_LU=int(lu.L.nnz + lu.U.nnz), solve_ms=1e3 * t_sol,
                        residual=float(np.linalg.norm(K @ x - b) / np.linalg.norm(b))))
    common.report(out, "direct_solve", "one sparse LU factorization and solve of the initial "
                                       "stiffness (scipy SuperLU, one thread)")


if __name__ == "__main__":
    main()
