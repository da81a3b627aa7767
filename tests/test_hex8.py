"""Tests of the total-Lagrangian hexahedron (kernels/hex8.py) against independent references."""
import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import naive_hex8 as nv
from dr_masonry.kernels import forces, hex8
from dr_masonry.kernels.assembly import gather_pair, node_row_map
from dr_masonry.kernels.plastic_damage import MP_HMAX, NMS
from dr_masonry.materials.plastic_damage import PlasticDamage
from dr_masonry.model import HEX_NATURAL

from conftest import box_mesh, distorted_element, elastic_params, run_forces, update_flags

# faces of a hexahedron, corners ordered so that (x_r x x_s) points outwards
FACES = ((0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7))
QUAD = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float)


def face_integrals(xe):
    """Surface integrals of one element: int N_a n dA (8, 3) and volume = int X . n dA / 3."""
    gp = np.array([-1.0, 1.0]) / np.sqrt(3.0)
    nda = np.zeros((8, 3))
    vol = 0.0
    for face in FACES:
        xq = xe[list(face)]
        for r in gp:
            for s in gp:
                N = 0.25 * (1 + QUAD[:, 0] * r) * (1 + QUAD[:, 1] * s)
                xr = 0.25 * (QUAD[:, 0] * (1 + QUAD[:, 1] * s)) @ xq
                xs = 0.25 * (QUAD[:, 1] * (1 + QUAD[:, 0] * r)) @ xq
                n = np.cross(xr, xs)
                for k, a in enumerate(face):
                    nda[a] += N[k] * n
                vol += (N @ xq) @ n / 3.0
    return nda, vol


def rotation(axis, angle):
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * Kx + (1 - np.cos(angle)) * Kx @ Kx


def assemble_K(X, conn, E, nu):
    dN, _, wdet, _ = hex8.hex_geometry(X, conn)
    ke = np.empty((24, 24))
    rows, cols, vals = [], [], []
    for e in range(conn.shape[0]):
        hex8.hex_stiffness(dN[e], wdet[e], E, nu, ke)
        dof = (3 * conn[e][:, None] + np.arange(3)).ravel()
        rows.append(np.repeat(dof, 24))
        cols.append(np.tile(dof, 24))
        vals.append(ke.ravel().copy())
    n = 3 * X.shape[0]
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(n, n))


# ---------------------------------------------------------------------------- geometry
def test_corner_table_matches_model():
    assert np.array_equal(hex8.CORNERS, HEX_NATURAL)


def test_geometry_against_reference_and_closed_forms():
    rng = np.random.default_rng(1)
    xe = distorted_element(rng)
    dN, geo, wdet, h = hex8.hex_geometry(xe, np.arange(8)[None])
    assert np.array_equal(geo, [0])
    dn_ref, wd_ref = nv.geometry(xe)
    assert np.allclose(dN[0], dn_ref, rtol=0, atol=1e-13)
    _, vol = face_integrals(xe)
    assert wdet.sum() == pytest.approx(vol, rel=1e-13)
    assert h[0] == pytest.approx(vol ** (1 / 3), rel=1e-13)
    # completeness: sum_a dN_a = 0 and sum_a X_a (x) dN_a = I at every Gauss point
    assert np.abs(dN[0].sum(axis=1)).max() < 1e-13
    assert np.allclose(np.einsum("ai,gaj->gij", xe, dN[0]), np.eye(3), atol=1e-13)
    # box: det J = V / 8 at every point
    _, _, wb, hb = hex8.hex_geometry(0.5 * (HEX_NATURAL + 1) * [2.0, 3.0, 4.0], np.arange(8)[None])
    assert np.allclose(wb, 3.0) and hb[0] == pytest.approx(24.0 ** (1 / 3))


def test_geometry_rejects_bad_input():
    X, conn = box_mesh((2, 1, 1))
    bad = conn.copy()
    bad[1] = bad[1][[1, 0, 3, 2, 5, 4, 7, 6]]  # mirrored corner order: inverted element
    with pytest.raises(hex8.HexMeshError, match="element 1"):
        hex8.hex_geometry(X, bad)
    with pytest.raises(hex8.HexMeshError, match="conn"):
        hex8.hex_geometry(X, conn[:, :7])
    out = conn.copy()
    out[0, 3] = 99
    with pytest.raises(hex8.HexMeshError, match="element 0"):
        hex8.hex_geometry(X, out)
    Xn = X.copy()
    Xn[2, 1] = np.nan
    with pytest.raises(hex8.HexMeshError, match="NaN"):
        hex8.hex_geometry(Xn, conn)
    with pytest.raises(hex8.HexMeshError, match="conn must be an integer array"):
        hex8.hex_geometry(X, conn.astype(float))


# ---------------------------------------------------------------------------- forces
@pytest.mark.parametrize("seed", range(4))
def test_forces_match_numpy_reference(seed):
    """Random distorted elements, random large displacements, per-element materials."""
    rng = np.random.default_rng(seed)
    ne = 5
    X = np.concatenate([distorted_element(rng) + 3.0 * e for e in range(ne)])
    conn = np.arange(8 * ne, dtype=np.int64).reshape(ne, 8)
    U = rng.uniform(-0.15, 0.15, X.shape)
    mats = [(rng.uniform(1e9, 3e10), rng.uniform(0.0, 0.45)) for _ in range(3)]
    params = np.array([elastic_params(E, nu) for E, nu in mats])
    elem_mat = rng.integers(0, 3, ne).astype(np.int64)
    f_elem, energy, _ = run_forces(U, X, conn, None, None, elem_mat, params)
    for e in range(ne):
        E, nu = mats[elem_mat[e]]
        f_ref, en_ref, _, _ = nv.element_forces(X[conn[e]], U[conn[e]], E, nu)
        assert np.abs(f_elem[e] - f_ref).max() <= 1e-12 * np.abs(f_ref).max()
        assert energy[e] == pytest.approx(en_ref, rel=1e-12)


def test_damaging_material_below_cracking_is_elastic():
    """A plastic-damage material at small strain: SVK forces, state written per Gauss point."""
    rng = np.random.default_rng(8)
    X, conn = 0.05 * distorted_element(rng), np.arange(8, dtype=np.int64)[None]  # h < h_max
    mat = PlasticDamage(E=5e9, nu=0.15, density=1800.0)
    U = rng.uniform(-5e-7, 5e-7, X.shape)
    dN, geo, wdet, h = hex8.hex_geometry(X, conn)
    s_old = np.tile(mat.initial_state(), (1, 8, 1))
    s_new = np.full_like(s_old, np.nan)
    f_elem, energy = np.empty((1, 8, 3)), np.empty(1)
    forces.hex_forces(U, conn, np.array([0]), dN, geo, wdet, h, np.zeros(1, np.int64),
                    mat.params_array()[None, :], s_old, s_new, *update_flags(1), f_elem, energy)
    f_ref, en_ref, _, _ = nv.element_forces(X, U, 5e9, 0.15)
    assert np.abs(f_elem[0] - f_ref).max() <= 1e-10 * np.abs(f_ref).max()
    assert energy[0] == pytest.approx(en_ref, rel=1e-10)
    assert np.array_equal(s_new, s_old)


def test_pristine_elements_skip_the_state_bit_for_bit():
    """Virgin elements in their elastic range take the elastic path without the state (forces,
    energies bit for bit those of the full update); one that yields goes through the full
    update, is marked dirty and is reset to its committed state when it is elastic again."""
    rng = np.random.default_rng(11)
    X, conn = box_mesh((4, 2, 2), size=(0.4, 0.2, 0.2))
    ne = conn.shape[0]
    mat = PlasticDamage(E=5e9, nu=0.15, density=1800.0)
    dN, geo, wdet, h = hex8.hex_geometry_shared(X, conn)
    virgin = np.tile(mat.initial_state(), (ne, 1))
    s_old = np.ascontiguousarray(np.repeat(virgin[:, None, :], 8, axis=1))
    p = mat.params_array()
    hmax = np.full(ne, p[MP_HMAX])
    pristine = hex8.pristine_elements(s_old, virgin, h, hmax)
    assert np.all(pristine == 1)
    args = (conn, np.arange(ne), dN, geo, wdet, h, np.zeros(ne, np.int64), p[None, :], s_old)

    def evaluate(U, s_new, pristine, dirty):
        f, en = np.full((ne, 8, 3), np.nan), np.full(ne, np.nan)
        forces.hex_forces(U, *args, s_new, pristine, dirty, f, en)
        return f, en

    elastic = rng.uniform(-2e-7, 2e-7, X.shape)
    # a strain growing along x: the elements at one end crack, the others stay elastic
    cracking = elastic + np.column_stack([6e-4 * X[:, 0] ** 2, 0 * X[:, 0], 0 * X[:, 0]])
    fast_new, dirty = s_old.copy(), np.zeros(ne, np.uint8)
    for U in (elastic, cracking, elastic, cracking):
        full_new = np.full_like(s_old, np.nan)
        f_full, en_full = evaluate(U, full_new, *update_flags(ne))
        f_fast, en_fast = evaluate(U, fast_new, pristine, dirty)
        assert np.array_equal(f_fast, f_full) and np.array_equal(en_fast, en_full)
        assert np.array_equal(fast_new, full_new)       # the trial state, wherever it was kept
        changed = np.any(full_new != s_old, axis=(1, 2))
        assert np.array_equal(dirty.astype(bool), changed)
    assert 0 < changed.sum() < ne
    # an element whose committed state left the virgin one, or whose length is clamped
    s_old[2, 5, 0] = 1e-3
    h_out = h.copy()
    h_out[3] = 2.0 * hmax[3]
    flags = hex8.pristine_elements(s_old, virgin, h_out, hmax)
    assert flags[2] == 0 and flags[3] == 0 and flags.sum() == ne - 2


def test_inactive_elements_untouched():
    rng = np.random.default_rng(7)
    X, conn = box_mesh((3, 2, 1))
    ne = conn.shape[0]
    dN, geo, wdet, h = hex8.hex_geometry_shared(X, conn)
    assert dN.shape[0] == 1 and np.all(geo == 0)  # identical boxes share one table
    params = elastic_params(1e10, 0.2)[None, :]
    f_elem = np.full((ne, 8, 3), -7.0)
    energy = np.full(ne, -7.0)
    s_old, s_new = np.zeros((ne, 8, NMS)), np.full((ne, 8, NMS), -7.0)
    active = np.array([4, 1], dtype=np.int64)
    forces.hex_forces(rng.normal(0, 1e-3, X.shape), conn, active, dN, geo, wdet, h,
                    np.zeros(ne, np.int64), params, s_old, s_new, *update_flags(ne), f_elem, energy)
    idle = np.setdiff1d(np.arange(ne), active)
    assert np.all(f_elem[idle] == -7.0) and np.all(energy[idle] == -7.0)
    assert np.all(s_new[idle] == -7.0)
    assert np.all(f_elem[active] != -7.0) and np.all(energy[active] > 0.0)


def _patch_mesh(rng):
    X, conn = box_mesh((2, 2, 2))
    X = X + rng.uniform(-0.12, 0.12, X.shape) * 0.5
    return X, conn


@pytest.mark.parametrize("mesh", ["single", "2x2x2"])
def test_patch_linear_field(mesh):
    """Linear displacement: constant F, E, S; f_a = P . int N_a n dA; interior forces vanish."""
    rng = np.random.default_rng(3)
    if mesh == "single":
        X, conn = distorted_element(rng), np.arange(8, dtype=np.int64)[None]
    else:
        X, conn = _patch_mesh(rng)
    E, nu = 2e10, 0.25
    A = rng.uniform(-2e-3, 2e-3, (3, 3))
    U = X @ A.T + [1e-3, -2e-3, 5e-4]
    f_elem, energy, f_node = run_forces(U, X, conn, E, nu)
    F = np.eye(3) + A
    Et = 0.5 * (F.T @ F - np.eye(3))
    Ev = np.array([Et[0, 0], Et[1, 1], Et[2, 2], 2 * Et[1, 2], 2 * Et[0, 2], 2 * Et[0, 1]])
    lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    S = lam * np.trace(Et) * np.eye(3) + 2 * mu * Et
    P = F @ S
    vols = []
    for e in range(conn.shape[0]):
        nda, vol = face_integrals(X[conn[e]])
        vols.append(vol)
        assert np.allclose(f_elem[e], nda @ P.T, rtol=0, atol=1e-10 * np.abs(P).max())
    assert energy.sum() == pytest.approx(0.5 * Ev @ (np.r_[np.diag(S), S[1, 2], S[0, 2], S[0, 1]])
                                         * sum(vols), rel=1e-10)
    scale = np.abs(f_node).max()
    assert np.abs(f_node.sum(axis=0)).max() < 1e-12 * scale
    if mesh != "single":
        assert np.abs(f_node[13]).max() < 1e-12 * scale  # centre node of the 3x3x3 grid


@pytest.mark.parametrize("mesh", ["single", "4x2x1"])
def test_rigid_rotation_is_stress_free_and_forces_rotate(mesh):
    rng = np.random.default_rng(5)
    if mesh == "single":
        X, conn = distorted_element(rng), np.arange(8, dtype=np.int64)[None]
    else:
        X, conn = box_mesh((4, 2, 1), (2.0, 1.0, 0.5))
        X = X + rng.uniform(-0.05, 0.05, X.shape)
    E, nu = 3e10, 0.2
    R = rotation(rng.normal(size=3), 0.5 * np.pi)
    x0 = rng.normal(size=3)
    U = (X - x0) @ R.T + x0 - X + rng.normal(size=3)
    f_elem, energy, f_node = run_forces(U, X, conn, E, nu)
    V = sum(face_integrals(X[c])[1] for c in conn)
    lref = V ** (1 / 3)
    assert np.abs(f_elem).max() < 1e-9 * E * lref ** 2
    assert np.abs(energy).max() < 1e-9 * E * V
    # objectivity: rotated stretch gives the rotated forces of the stretch alone
    A = rng.uniform(-1e-2, 1e-2, (3, 3))
    fA, enA, _ = run_forces(X @ A.T, X, conn, E, nu)
    fRA, enRA, _ = run_forces(X @ ((R @ (np.eye(3) + A)).T) - X, X, conn, E, nu)
    assert np.allclose(fRA, fA @ R.T, rtol=0, atol=1e-11 * np.abs(fA).max())
    assert np.allclose(enRA, enA, rtol=1e-10)


def _mixed_mesh(rng):
    """Boxes, distorted elements, translated copies of one distorted element (one with 1e-15 m
    noise) and a copy with one corner moved by 1 um. Returns X, conn and the expected tables."""
    X, conn = box_mesh((4, 3, 2), (0.8, 0.3, 0.2))
    moved = X[:, 0] > 0.5  # elements with x <= 0.4 m stay boxes: 2 x 3 x 2 = 12, one table
    X[moved] += rng.uniform(-0.02, 0.02, (moved.sum(), 3))  # 12 distinct distorted elements
    xd = 0.1 * distorted_element(rng)
    xd2 = xd.copy()
    xd2[6] += 1e-6
    extra = [xd + [2.0, 0.0, 0.0], xd + [3.0, 1.0, 0.0] + rng.uniform(-1e-15, 1e-15, (8, 3)),
             xd + [4.0, 0.0, 5.0], xd2 + [5.0, 0.0, 0.0]]
    conn = np.concatenate([conn, X.shape[0] + np.arange(32).reshape(4, 8)])
    return np.concatenate([X] + extra), conn, 1 + 12 + 1 + 1


def test_shared_tables_match_per_element_tables():
    """Shared derivative tables give the forces, energies and states of per-element tables."""
    rng = np.random.default_rng(12)
    X, conn, n_tables = _mixed_mesh(rng)
    ne = conn.shape[0]
    dN, geo, wdet, h = hex8.hex_geometry_shared(X, conn)
    dNe, geoe, wde, he = hex8.hex_geometry(X, conn)
    assert dN.shape == (n_tables, 8, 8, 3) and geo.shape == (ne,) and geo.dtype == np.int64
    assert np.unique(geo[:24].reshape(4, 3, 2)[:2]).size == 1  # the boxes (x index < 2)
    assert geo[-4] == geo[-3] == geo[-2] != geo[-1]
    assert np.allclose(dN[geo], dNe, rtol=0, atol=1e-12 * np.abs(dNe).max())
    assert np.allclose(wdet, wde, rtol=1e-12, atol=0) and np.allclose(h, he, rtol=1e-12, atol=0)
    # half elastic material (fast path), half damaging material in its elastic range
    mats = [PlasticDamage.elastic(5e9, 0.2, 1800.0), PlasticDamage(E=5e9, nu=0.15, density=1800.0)]
    params = np.array([m.params_array() for m in mats])
    elem_mat = rng.integers(0, 2, ne).astype(np.int64)
    s0 = np.array([m.initial_state() for m in mats])[elem_mat]
    s_old = np.ascontiguousarray(np.repeat(s0[:, None, :], 8, axis=1))
    U = rng.uniform(-2e-6, 2e-6, X.shape)
    out = []
    for d, g, w, hh in ((dN, geo, wdet, h), (dNe, geoe, wde, he)):
        f, en, sn = np.full((ne, 8, 3), np.nan), np.full(ne, np.nan), np.full_like(s_old, -1.0)
        forces.hex_forces(U, conn, np.arange(ne), d, g, w, hh, elem_mat, params, s_old, sn,
                        *update_flags(ne), f, en)
        out.append((f, en, sn))
    (f, en, sn), (fe, ene, sne) = out
    assert np.abs(f - fe).max() <= 1e-12 * np.abs(fe).max()
    assert np.allclose(en, ene, rtol=1e-12, atol=0) and np.all(en > 0.0)
    assert np.all(sn[elem_mat == 0] == -1.0)  # elastic fast path writes no state
    assert np.array_equal(sn[elem_mat == 1], s_old[elem_mat == 1])  # no damage at this strain


def test_shared_geometry_input_errors():
    rng = np.random.default_rng(13)
    X, conn, _ = _mixed_mesh(rng)
    bad = conn.copy()
    bad[25] = bad[25][[1, 0, 3, 2, 5, 4, 7, 6]]  # inverted copy of the distorted element
    with pytest.raises(hex8.HexMeshError, match="element 25 "):
        hex8.hex_geometry_shared(X, bad)
    flat = X.copy()
    flat[conn[27]] = flat[conn[27, 0]]  # degenerate (all corners at one point)
    with pytest.raises(hex8.HexMeshError, match="element 27 "):
        hex8.hex_geometry_shared(flat, conn)
    with pytest.raises(hex8.HexMeshError, match="conn"):
        hex8.hex_geometry_shared(X, conn[:, :7])
    dN, geo, wdet, h = hex8.hex_geometry_shared(X, conn[:0])
    assert dN.shape == (0, 8, 8, 3) and geo.shape == (0,) and wdet.shape == (0, 8)


# ---------------------------------------------------------------------------- stiffness
def test_stiffness_is_jacobian_of_forces():
    rng = np.random.default_rng(11)
    xe = distorted_element(rng)
    E, nu = 1e10, 0.3
    conn = np.arange(8, dtype=np.int64)[None]
    dN, _, wdet, _ = hex8.hex_geometry(xe, conn)
    ke = np.empty((24, 24))
    hex8.hex_stiffness(dN[0], wdet[0], E, nu, ke)
    assert np.allclose(ke, nv.element_stiffness(xe, E, nu), rtol=0, atol=1e-12 * np.abs(ke).max())
    step = 1e-6
    kfd = np.empty((24, 24))
    for j in range(24):
        du = np.zeros(24)
        du[j] = step
        fp = run_forces(du.reshape(8, 3), xe, conn, E, nu)[0][0].ravel()
        fm = run_forces(-du.reshape(8, 3), xe, conn, E, nu)[0][0].ravel()
        kfd[:, j] = (fp - fm) / (2 * step)
    assert np.abs(kfd - ke).max() < 1e-7 * np.abs(ke).max()


def test_cantilever_converges_to_timoshenko():
    """Tip-loaded clamped cantilever L/b = 10, nu = 0: tip deflection -> Timoshenko."""
    L, b, E, nu, P = 10.0, 1.0, 1e9, 0.0, 1e4
    I, A, G, kappa = b ** 4 / 12, b * b, E / 2, 5.0 / 6.0
    exact = P * L ** 3 / (3 * E * I) + P * L / (kappa * G * A)
    errors = []
    for k in (1, 2, 4):
        n = (10 * k, k, k)
        X, conn = box_mesh(n, (L, b, b))
        K = assemble_K(X, conn, E, nu)
        tip = np.flatnonzero(np.isclose(X[:, 0], L))
        # consistent load of a uniform shear traction: bilinear tributary weights on the tip face
        j = np.rint(X[tip, 1] / b * k)
        m = np.rint(X[tip, 2] / b * k)
        wt = np.where((j == 0) | (j == k), 0.5, 1.0) * np.where((m == 0) | (m == k), 0.5, 1.0)
        f = np.zeros(3 * X.shape[0])
        f[3 * tip + 2] = -P * wt / wt.sum()
        free = np.ones(3 * X.shape[0], bool)
        clamp = np.flatnonzero(np.isclose(X[:, 0], 0.0))
        free[(3 * clamp[:, None] + np.arange(3)).ravel()] = False
        u = np.zeros_like(f)
        u[free] = spla.spsolve(K[free][:, free].tocsc(), f[free])
        errors.append((exact + u[3 * tip + 2].mean()) / exact)  # > 0: too stiff
    assert errors[0] > errors[1] > errors[2] > 0.0
    assert errors[0] / errors[1] > 2.5 and errors[1] / errors[2] > 3.0  # about O(h^2)
    assert errors[2] < 0.04
    # Richardson extrapolation of the two finest meshes (order 2) hits the beam theory
    assert abs(errors[2] - (errors[1] - errors[2]) / 3.0) < 0.01


def test_gershgorin_bound_brackets_max_eigenvalue():
    rng = np.random.default_rng(2)
    X, conn = box_mesh((3, 2, 2), (1.5, 0.6, 0.8))
    moved = X[:, 0] > 0.6  # elements off these nodes stay identical boxes (one shared table)
    X[moved] += rng.uniform(-0.04, 0.04, (moved.sum(), 3))
    E, nu = 2e10, 0.2
    dN, geo, wdet, _ = hex8.hex_geometry_shared(X, conn)
    ne = conn.shape[0]
    assert dN.shape[0] == 1 + 8  # the 4 boxes at x < 0.5 m, then 8 distorted elements
    bound = hex8.stiffness_rowsum(conn, dN, geo, wdet, np.full(ne, E), np.full(ne, nu), X.shape[0])
    K = assemble_K(X, conn, E, nu)
    rows = np.asarray(abs(K).sum(axis=1)).ravel().reshape(-1, 3)
    assert np.all(rows <= bound[:, None] * (1 + 1e-12))
    lmax = spla.eigsh(K, k=1, which="LA", return_eigenvectors=False)[0]
    assert lmax <= bound.max() <= 3.0 * lmax
    with pytest.raises(ValueError, match="nu"):
        hex8.stiffness_rowsum(conn, dN, geo, wdet, np.full(ne, E), np.full(ne, 0.5), X.shape[0])
    with pytest.raises(ValueError, match="geo"):
        hex8.stiffness_rowsum(conn, dN, geo + 9, wdet, np.full(ne, E), np.full(ne, nu), X.shape[0])


# ---------------------------------------------------------------------------- mass, gather
def test_lumped_mass():
    rng = np.random.default_rng(4)
    X, conn = _patch_mesh(rng)
    _, _, wdet, _ = hex8.hex_geometry(X, conn)
    rho = rng.uniform(1500, 2500, conn.shape[0])
    m = hex8.lumped_mass(conn, wdet, rho, X.shape[0])
    ref = np.zeros(X.shape[0])
    V = 0.0
    for e, c in enumerate(conn):
        np.add.at(ref, c, nv.element_mass(X[c], rho[e]))
        V += rho[e] * face_integrals(X[c])[1]
    assert np.allclose(m, ref, rtol=1e-12)
    assert m.sum() == pytest.approx(V, rel=1e-12)
    Xb = 0.5 * (HEX_NATURAL + 1) * [0.3, 0.2, 0.1]
    _, _, wb, _ = hex8.hex_geometry(Xb, np.arange(8)[None])
    assert np.allclose(hex8.lumped_mass(np.arange(8)[None], wb, [2000.0], 8), 2000 * 0.006 / 8)
    with pytest.raises(ValueError, match="rho_elem"):
        hex8.lumped_mass(conn, wdet, -rho, X.shape[0])


def test_node_map_and_gather():
    rng = np.random.default_rng(6)
    X, conn = box_mesh((3, 2, 2))
    nn = X.shape[0] + 2  # two nodes without elements
    ptr, idx = node_row_map(conn, nn)
    for n in range(nn):
        e, a = np.nonzero(conn == n)
        assert sorted(idx[ptr[n]:ptr[n + 1]]) == sorted(8 * e + a)
    f_elem = rng.normal(size=(conn.shape[0], 8, 3))
    ref = np.zeros((nn, 3))
    np.add.at(ref, conn.ravel(), f_elem.reshape(-1, 3))
    f_node = np.full((nn, 3), np.nan)   # overwritten, nodes without elements included
    k = 5   # the elements in two buffers with maps of their own, as hexahedra and contacts
    gather_pair(f_elem[:k].reshape(-1, 3), *node_row_map(conn[:k], nn),
                f_elem[k:].reshape(-1, 3), *node_row_map(conn[k:], nn), f_node)
    assert np.allclose(f_node, ref, rtol=1e-14, atol=1e-14)
