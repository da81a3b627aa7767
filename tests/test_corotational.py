"""Tests of the corotational hexahedron (kernels/hex8.py: ``polar_rotation``, ``corot_local``,
``corot_global``, ``corot_damaging``, ``corot_tables`` and their path in the force kernel) against
numpy/scipy references and the total-Lagrangian element: linear elastic elements, and the damaging
material's Gauss-point update of the linear strains in the rotated frame."""
import numpy as np
import pytest
import scipy.linalg
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

import naive_hex8 as nv
from dr_masonry.kernels import forces, hex8
from dr_masonry.kernels.plastic_damage import MS_DT, MS_EPSP, NMS, gp_update
from dr_masonry.materials.plastic_damage import PlasticDamage

from conftest import box_mesh, distorted_element, run_forces

E, NU = 3e10, 0.2


def _forces(U, X, conn, corot=True):
    """Element forces (ne, 8, 3) N and energies (ne,) J of an elastic mesh: the corotational
    path of a run (``corot``) or every element at its Gauss points."""
    return run_forces(U, X, conn, E, NU, corot=corot)[:2]


def _reference(xe, ue):
    """numpy/scipy corotational element: rotation of the polar decomposition of the
    volume-averaged F (naive Gauss rule), K of the naive total-Lagrangian element."""
    dn, wd = nv.geometry(xe)
    F = np.eye(3) + sum(w * ue.T @ d for w, d in zip(wd, dn)) / wd.sum()
    R, _ = scipy.linalg.polar(F)
    x = xe + ue
    d = ((x - x[0]) @ R - (xe - xe[0])).ravel()
    fl = nv.element_stiffness(xe, E, NU) @ d
    return (fl.reshape(8, 3) @ R.T), 0.5 * d @ fl


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3),
       st.lists(st.floats(-0.3, 0.3), min_size=6, max_size=6))
def test_polar_rotation_of_a_stretched_rotation(rotvec, stretch):
    """F = Q S with S symmetric positive definite: the iteration returns Q and det F."""
    Q = Rotation.from_rotvec(rotvec).as_matrix()
    a, b, c, d, e, f = stretch
    S = np.eye(3) + np.array([[a, f, e], [f, b, d], [e, d, c]]) / 2.0
    F = Q @ S
    R = np.empty((3, 3))
    det = hex8.polar_rotation(*F.ravel(), R)
    assert det == pytest.approx(np.linalg.det(F), rel=1e-12)
    np.testing.assert_allclose(R, Q, rtol=0, atol=1e-12)


def test_polar_rotation_of_an_inverted_gradient_is_not_written():
    R = np.full((3, 3), 7.0)
    assert hex8.polar_rotation(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -0.5, R) < 0.0
    assert np.all(R == 7.0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_forces_match_numpy_reference(seed):
    """Distorted elements (one table each), a large rotation plus strains of 1e-3: the kernel's
    forces and energy are the numpy corotational element's."""
    rng = np.random.default_rng(seed)
    xs = [distorted_element(rng) + [3.0 * k, 0.0, 0.0] for k in range(3)]
    X = np.concatenate(xs)
    conn = np.arange(24, dtype=np.int64).reshape(3, 8)
    Q = Rotation.from_rotvec(rng.normal(size=3)).as_matrix()
    U = (X @ Q.T - X) + rng.uniform(-1e-3, 1e-3, X.shape) + rng.normal(size=3)
    f, en = _forces(U, X, conn)
    for e in range(3):
        fr, er = _reference(X[conn[e]], U[conn[e]])
        np.testing.assert_allclose(f[e], fr, rtol=0, atol=1e-9 * np.abs(fr).max())
        assert en[e] == pytest.approx(er, rel=1e-9)


def test_rigid_motion_is_force_free_and_forces_rotate():
    """A 100-element wall of shared tables (two force tasks) turned by 1.2 rad and moved: no
    force, no energy; a rotated stretch gives the rotated forces of the stretch alone."""
    rng = np.random.default_rng(4)
    X, conn = box_mesh((10, 2, 5), (2.0, 0.2, 1.0))
    Q = Rotation.from_rotvec(1.2 * np.array([0.6, -0.48, 0.64])).as_matrix()
    U = (X @ Q.T - X) + [3.0, -1.0, 2.0]
    f, en = _forces(U, X, conn)
    assert np.abs(f).max() < 1e-9 * E * 0.2 ** 2
    assert np.abs(en).max() < 1e-9 * E * 0.2 ** 3
    A = rng.uniform(-1e-4, 1e-4, (3, 3))
    A = 0.5 * (A + A.T)   # a pure stretch: no rotation of its own
    fA, enA = _forces(X @ A.T, X, conn)
    fQA, enQA = _forces(X @ (Q @ (np.eye(3) + A)).T - X, X, conn)
    np.testing.assert_allclose(fQA, fA @ Q.T, rtol=0, atol=1e-9 * np.abs(fA).max())
    np.testing.assert_allclose(enQA, enA, rtol=1e-8)


def test_agrees_with_total_lagrangian_element_to_first_order():
    """Under a 0.7 rad rotation and strains eps, the corotational and the total-Lagrangian
    (St.Venant-Kirchhoff) elements differ by O(eps) relatively: 10 x smaller strains, 10 x
    smaller relative difference."""
    rng = np.random.default_rng(7)
    X, conn = box_mesh((4, 2, 2), (0.8, 0.2, 0.3))
    X = X + rng.uniform(-0.01, 0.01, X.shape)
    Q = Rotation.from_rotvec([0.0, 0.7, 0.0]).as_matrix()
    B = rng.uniform(-1.0, 1.0, X.shape)
    rel = []
    for eps in (1e-3, 1e-4):
        U = (X + eps * B) @ Q.T - X
        fc, ec = _forces(U, X, conn)
        ft, et = _forces(U, X, conn, corot=False)
        rel.append(np.abs(fc - ft).max() / np.abs(ft).max())
        assert ec.sum() == pytest.approx(et.sum(), rel=30 * eps)
    assert rel[0] < 30 * 1e-3
    assert 5.0 < rel[0] / rel[1] < 20.0


def test_inverted_element_gives_nan_for_the_guards():
    X, conn = box_mesh((1, 1, 1))
    U = np.zeros_like(X)
    U[:, 2] = -2.0 * X[:, 2]   # z -> -z: turned inside out
    f, en = _forces(U, X, conn)
    assert np.all(np.isnan(f)) and np.isnan(en[0])


def test_tables_one_per_shape_and_material():
    """Translated copies share a table; another material or shape gets its own; elements not
    listed get none (-1), and ``hex_forces`` refuses to run them with the tables."""
    xe, c1 = box_mesh((1, 1, 1), (0.2, 0.2, 0.2))
    xe = xe[c1[0]]
    X = np.concatenate([xe, xe + [0.3, 0.0, 0.0], xe * [1.0, 1.0, 1.5] + [0.6, 0.0, 0.0]])
    conn = np.arange(24, dtype=np.int64).reshape(3, 8)   # element 2 a taller shape
    dN, geo, wdet, _ = hex8.hex_geometry_shared(X, conn)
    params = np.stack([PlasticDamage.elastic(E, NU, 2000.0).params_array(),
                       PlasticDamage.elastic(2 * E, NU, 2000.0).params_array()])
    conn4 = np.concatenate([conn, conn[:1]])   # element 3: element 0 in the second material
    emat = np.array([0, 0, 0, 1])
    ke, _, kxo, kdn, kid = hex8.corot_tables(X, conn4, dN, np.r_[geo, geo[0]],
                                          np.concatenate([wdet, wdet[:1]]), emat, params,
                                          np.array([0, 1, 3]))
    assert kid[0] == kid[1] and kid[2] == -1 and kid[3] not in (-1, kid[0])
    np.testing.assert_allclose(ke[kid[3]], 2 * ke[kid[0]], rtol=1e-14)
    np.testing.assert_allclose(ke[kid[0]], nv.element_stiffness(X[conn[0]], E, NU),
                               rtol=0, atol=1e-9 * np.abs(ke[kid[0]]).max())
    np.testing.assert_allclose(kdn[kid[0]].sum(axis=0), 0.0, atol=1e-12)
    np.testing.assert_allclose(kxo[kid[0]], X[conn[0]] - X[conn[0, 0]])
    h = np.zeros(4)
    s = np.zeros((4, 8, NMS))
    with pytest.raises(ValueError, match="element 2 .* no corotational table"):
        forces.hex_forces(np.zeros_like(X), conn4, np.arange(4), dN, np.r_[geo, geo[0]],
                          np.concatenate([wdet, wdet[:1]]), h, emat, params, s, s.copy(),
                          np.ones(4, np.uint8), np.zeros(4, np.uint8), np.zeros((4, 8, 3)),
                          np.zeros(4), corot=(ke, np.zeros((ke.shape[0], 24, 48)), kxo, kdn, kid))


# ---------------------------------------------------------------------------- damaging materials
def _damaging(X, conn, U, pristine, s_new=None, dirty=None, corot=True):
    """Forces, energies, trial states and dirty flags of a damaging material's elements on the
    corotational path of a run (``pristine``: the virgin-state flags given to the kernel;
    ``s_new``, ``dirty``: those of an earlier call, carried on; ``corot=False``: the
    total-Lagrangian element instead)."""
    ne = conn.shape[0]
    mat = PlasticDamage(E=5e9, nu=0.15, density=1800.0)
    dN, geo, wdet, h = hex8.hex_geometry_shared(X, conn)
    p = mat.params_array()[None, :]
    emat = np.zeros(ne, np.int64)
    tables = hex8.corot_tables(X, conn, dN, geo, wdet, emat, p, np.arange(ne)) if corot else None
    s_old = np.ascontiguousarray(np.tile(mat.initial_state(), (ne, 8, 1)))
    s_new = np.full_like(s_old, np.nan) if s_new is None else s_new
    f, en = np.full((ne, 8, 3), np.nan), np.full(ne, np.nan)
    dirty = np.zeros(ne, np.uint8) if dirty is None else dirty
    forces.hex_forces(np.ascontiguousarray(U), conn, np.arange(ne), dN, geo, wdet, h, emat, p,
                      s_old, s_new, pristine, dirty, f, en, corot=tables)
    return f, en, s_new, dirty, mat, s_old


def _damaging_reference(xe, ue, mat):
    """numpy corotational element of a damaging material: rotation of the polar decomposition
    of the volume-averaged F, linear strains B_g d of the local displacements, the kernel's
    Gauss-point update (``gp_update``, tested on its own) and f = R sum_g w B_g^T sigma_g."""
    dn, wd = nv.geometry(xe)
    F = np.eye(3) + sum(w * ue.T @ d for w, d in zip(wd, dn)) / wd.sum()
    R, _ = scipy.linalg.polar(F)
    x = xe + ue
    d = ((x - x[0]) @ R - (xe - xe[0])).ravel()
    p = mat.params_array()
    h = np.cbrt(wd.sum())
    fl, energy = np.zeros(24), 0.0
    states = np.empty((8, NMS))
    for g in range(8):
        B = nv.b_matrix(np.eye(3), dn[g])
        eps, sig = B @ d, np.empty(6)
        gp_update(p, h, eps, mat.initial_state(), states[g], sig)
        fl += wd[g] * B.T @ sig
        energy += 0.5 * wd[g] * sig @ (eps - states[g, MS_EPSP:MS_EPSP + 6])
    return fl.reshape(8, 3) @ R.T, energy, states


@pytest.mark.parametrize("pristine", [0, 1])
def test_damaging_element_matches_numpy_reference(pristine):
    """A distorted brick-sized element, turned by 0.7 rad and stretched past cracking: forces,
    energy and Gauss-point states as the numpy reference, whether the kernel starts from the
    virgin state's elastic check (``pristine``) or not; the element is then marked dirty."""
    rng = np.random.default_rng(5)
    xe = 0.05 * distorted_element(rng)
    Q = Rotation.from_rotvec([0.3, -0.5, 0.4]).as_matrix()
    strain = np.array([[1.2e-3, 2e-4, 0.0], [2e-4, -3e-4, 1e-4], [0.0, 1e-4, 2e-4]])
    ue = (xe - xe[0]) @ (Q @ (np.eye(3) + strain)).T - (xe - xe[0])
    conn = np.arange(8, dtype=np.int64)[None]
    f, en, s_new, dirty, mat, s_old = _damaging(xe, conn, ue, np.full(1, pristine, np.uint8))
    f_ref, en_ref, states = _damaging_reference(xe, ue, mat)
    assert np.any(states[:, MS_DT] > 0.0)   # cracked
    np.testing.assert_allclose(f[0], f_ref, rtol=0, atol=1e-9 * np.abs(f_ref).max())
    assert en[0] == pytest.approx(en_ref, rel=1e-9)
    np.testing.assert_allclose(s_new[0], states, rtol=1e-9, atol=1e-15)
    assert dirty[0] == pristine


def test_damaging_elements_in_their_elastic_range_skip_the_state():
    """Virgin elements in their elastic range: the elastic check's K d equals the full update's
    sum_g w B_g^T D B_g d to rounding and leaves the state alone; elements that crack go
    through the update and are marked dirty, then reset when they are elastic again."""
    rng = np.random.default_rng(11)
    X, conn = box_mesh((4, 2, 2), size=(0.4, 0.2, 0.2))
    ne = conn.shape[0]
    Q = Rotation.from_rotvec([0.2, 0.1, -0.6]).as_matrix()
    elastic = rng.uniform(-2e-7, 2e-7, X.shape)
    cracking = elastic + np.column_stack([6e-4 * X[:, 0] ** 2, 0 * X[:, 0], 0 * X[:, 0]])
    kept, dirty, cracked = None, None, None
    for step, U in enumerate((elastic, cracking, elastic, cracking)):
        U = (X + U) @ Q.T - X
        f_full, en_full, full_new, _, _, s_old = _damaging(X, conn, U, np.zeros(ne, np.uint8))
        f_fast, en_fast, kept, dirty, _, _ = _damaging(X, conn, U, np.ones(ne, np.uint8), kept,
                                                       dirty)
        np.testing.assert_allclose(f_fast, f_full, rtol=0, atol=1e-11 * np.abs(f_full).max())
        np.testing.assert_allclose(en_fast, en_full, rtol=1e-11)
        changed = np.any(full_new != s_old, axis=(1, 2))
        assert np.array_equal(dirty.astype(bool), changed)
        assert np.array_equal(kept[changed], full_new[changed])
        rest = kept[~changed]   # never written (NaN) or reset to the committed state
        assert np.all(np.isnan(rest) | (rest == s_old[~changed]))
        if step == 1:
            cracked = changed
        if step == 2:   # the elements that cracked are elastic again: reset
            assert not changed.any() and np.array_equal(kept[cracked], s_old[cracked])
    assert 0 < changed.sum() < ne


def test_damaging_element_is_objective():
    """A rigid rotation on top of a cracking deformation rotates the forces and changes neither
    the energy nor the Gauss-point states."""
    rng = np.random.default_rng(3)
    xe = 0.05 * distorted_element(rng)
    conn = np.arange(8, dtype=np.int64)[None]
    ue = (xe - xe[0]) @ np.array([[1.5e-3, 0, 0], [3e-4, -2e-4, 0], [0, 0, 1e-4]]).T
    Q = Rotation.from_rotvec([1.1, 0.4, -0.8]).as_matrix()
    f0, en0, s0, *_ = _damaging(xe, conn, ue, np.zeros(1, np.uint8))
    f1, en1, s1, *_ = _damaging(xe, conn, (xe + ue) @ Q.T - xe, np.zeros(1, np.uint8))
    assert np.any(s0[0, :, MS_DT] > 0.0)
    np.testing.assert_allclose(f1[0], f0[0] @ Q.T, rtol=0, atol=1e-8 * np.abs(f0).max())
    assert en1[0] == pytest.approx(en0[0], rel=1e-8)
    np.testing.assert_allclose(s1, s0, rtol=1e-7, atol=1e-14)


def test_damaging_element_agrees_with_total_lagrangian_element_to_first_order():
    """Turned by 0.7 rad, the corotational and the total-Lagrangian elements of a damaging
    material differ by O(strain) relatively: cracked at strains of 1.2e-3 and 6e-4 (forces
    within 3 x the largest strain, the same damage to 1e-4), and 10 x closer at 10 x smaller
    elastic strains."""
    rng = np.random.default_rng(5)
    xe = 0.05 * distorted_element(rng)
    conn = np.arange(8, dtype=np.int64)[None]
    Q = Rotation.from_rotvec([0.0, 0.7, 0.0]).as_matrix()
    strain = np.array([[1.2e-3, 2e-4, 0.0], [2e-4, -3e-4, 1e-4], [0.0, 1e-4, 2e-4]])
    rel = {}
    for scale in (1.0, 0.5, 0.1, 0.01):
        ue = (xe - xe[0]) @ (Q @ (np.eye(3) + scale * strain)).T - (xe - xe[0])
        fc, ec, sc, *_ = _damaging(xe, conn, ue, np.zeros(1, np.uint8))
        ft, et, st_, *_ = _damaging(xe, conn, ue, np.zeros(1, np.uint8), corot=False)
        rel[scale] = np.abs(fc - ft).max() / np.abs(ft).max()
        assert ec[0] == pytest.approx(et[0], rel=3 * scale * 1.2e-3)
        if scale >= 0.5:
            assert sc[0, :, MS_DT].max() > 0.02   # cracked
            np.testing.assert_allclose(sc[0, :, MS_DT], st_[0, :, MS_DT], rtol=0, atol=1e-4)
        assert rel[scale] < 3 * scale * 1.2e-3
    assert 5.0 < rel[0.1] / rel[0.01] < 20.0
