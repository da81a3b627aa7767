"""The thrust-line LP of ``tests/limit_analysis.py`` against Heyman / Milankovitch's minimum
thickness of the semicircular arch and against the virtual work of its own mechanism."""
import math

import numpy as np
import pytest

import limit_analysis as la


def test_minimum_thickness_converges_to_the_continuous_arch():
    """t/R -> 0.1075 (Milankovitch; Heyman's approximation 0.106), intrados hinges ~54 deg from
    the crown, extrados hinges at the crown and springings."""
    r = la.minimum_thickness(1.0, 40)
    assert 0.106 <= r.value <= 0.1080
    assert r.hinges == (0, 8, 20, 32, 40)
    assert r.faces == (1, -1, 1, -1, 1)
    assert math.degrees(r.angles[3]) == pytest.approx(54.0, abs=5.0)
    coarse = [la.minimum_thickness(1.0, n).value for n in (8, 12, 20, 40)]
    assert np.all(np.diff(coarse) > 0)  # fewer joints, fewer places to hinge: thinner


def test_minimum_thickness_scales_with_radius_and_not_with_unit_weight():
    assert la.minimum_thickness(3.0, 12, gamma=2.0e4).value == pytest.approx(
        3.0 * la.minimum_thickness(1.0, 12).value, rel=1e-7)


def _mechanism_factor(R, t, n, hinges, faces):
    """Load factor of the four-hinge mechanism by virtual work (upper-bound side)."""
    theta = la.joint_angles(n)
    area, g = la.voussoirs(R, t, theta)
    pts = [(R + 0.5 * t * f) * np.array([math.cos(theta[i]), math.sin(theta[i])])
           for i, f in zip(hinges, faces)]
    a, b, c, d = pts

    def cross(u, v):
        return u[0] * v[1] - u[1] * v[0]
    # instantaneous centre of the middle body: lines a-b and d-c
    s = cross(d - a, c - d) / cross(b - a, c - d)
    ic = a + s * (b - a)
    w1 = 1.0
    w2 = w1 * np.dot(b - a, b - ic) / np.dot(b - ic, b - ic)
    w3 = w2 * np.dot(c - ic, c - d) / np.dot(c - d, c - d)
    centre = {1: (a, w1), 2: (ic, w2), 3: (d, w3)}
    num = den = 0.0
    for k in range(n):
        if not hinges[0] <= k < hinges[3]:
            continue  # on the abutments' side of the outer hinges: at rest
        body = 1 if k < hinges[1] else 2 if k < hinges[2] else 3
        o, w = centre[body]
        v = w * np.array([-(g[k, 1] - o[1]), g[k, 0] - o[0]])
        num += area[k] * v[1]
        den += area[k] * v[0]
    return num / den


@pytest.mark.parametrize("t", [0.15, 0.2, 0.3])
def test_tilting_factor_equals_the_virtual_work_of_its_mechanism(t):
    r = la.collapse_factor(1.0, t, 12)
    assert len(r.hinges) == 4 and r.faces == (-1, 1, -1, 1)
    assert r.value > 0
    assert _mechanism_factor(1.0, t, 12, r.hinges, r.faces) == pytest.approx(r.value, rel=1e-6)


def test_tilting_factor_grows_with_thickness():
    lam = [la.collapse_factor(1.0, t, 12).value for t in (0.12, 0.2, 0.3)]
    assert np.all(np.diff(lam) > 0)


def test_arch_below_its_minimum_thickness_has_no_tilting_factor():
    with pytest.raises(RuntimeError, match="not even stable"):
        la.collapse_factor(1.0, 0.09, 12)


def test_bad_parameters():
    with pytest.raises(ValueError, match="n must be"):
        la.joint_angles(0)
    with pytest.raises(ValueError, match="embrace"):
        la.joint_angles(4, 4.0)
