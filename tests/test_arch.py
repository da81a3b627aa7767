"""The voussoir-arch generator: geometry against the circles it is defined by, input errors."""
import math

import numpy as np
import pytest

from dr_masonry import JointLaw, Model, PlasticDamage
from dr_masonry.geometry import GeometryError, add_arch

MAT = PlasticDamage.reference()


def test_semicircular_arch_corners_lie_on_the_intrados_and_extrados():
    m = Model()
    a = add_arch(m, MAT, span=2.0, rise=1.0, thickness=0.2, depth=0.3, n=8, abutment_height=0.5)
    assert a.radius == pytest.approx(1.1) and a.embrace == pytest.approx(math.pi)
    assert len(a.voussoirs) == 8 and len(a.abutments) == 2 and a.base is None
    xc, zc = a.centre
    assert zc == pytest.approx(0.5)
    for b in a.voussoirs:
        c = m.block_corners[b]
        r = np.hypot(c[:, 0] - xc, c[:, 2] - zc)
        np.testing.assert_allclose(r[:4], 1.0, atol=1e-12)
        np.testing.assert_allclose(r[4:], 1.2, atol=1e-12)
    # each face in the (x, z) plane is the quadrilateral of area sin(pi/8) (Re^2 - Ri^2) / 2
    for b in a.voussoirs:
        q = m.block_corners[b][[0, 1, 5, 4]][:, [0, 2]]
        area = 0.5 * np.sum(q[:, 0] * np.roll(q[:, 1], -1) - np.roll(q[:, 0], -1) * q[:, 1])
        assert area == pytest.approx(0.5 * math.sin(math.pi / 8) * (1.2 ** 2 - 1.0 ** 2))
    assert m.block_fixed[a.abutments].all() and not m.block_fixed[a.voussoirs].any()
    m.check_overlaps(1e-6)


def test_segmental_arch_on_a_base():
    m = Model()
    a = add_arch(m, MAT, span=3.0, rise=0.75, thickness=0.25, depth=0.4, n=5,
                 abutment_height=0.6, support="base", joint=JointLaw.dry(0.7))
    ri = (1.5 ** 2 + 0.75 ** 2) / 1.5
    assert a.radius == pytest.approx(ri + 0.125)
    assert a.embrace == pytest.approx(2 * math.asin(1.5 / ri))
    c = m.block_corners
    assert np.isclose(c[a.voussoirs[0]][0], [-1.5, 0.0, 0.6]).all()    # left intrados springing
    assert np.isclose(c[a.voussoirs[-1]][1], [1.5, 0.0, 0.6]).all()    # right one
    crown = max(c[b][:4, 2].max() for b in a.voussoirs)
    assert crown < 0.6 + 0.75    # flat faces: the crown joint lies below the circle's top
    assert m.block_fixed[a.base] and not m.block_fixed[a.abutments].any()
    assert np.allclose(c[a.abutments[0]][:4, 2], 0.25)                # on the base's top
    m.check_overlaps(1e-6)


@pytest.mark.parametrize("kw, match", [
    (dict(rise=1.5), "rise 1.5 m exceeds half the span"),
    (dict(span=-1.0), "span must be a positive length"),
    (dict(thickness=float("nan")), "thickness must be"),
    (dict(n=0), "n \\(voussoirs\\) must be an integer"),
    (dict(n=2.5), "n \\(voussoirs\\) must be an integer"),
    (dict(support="glued"), "support must be one of"),
    (dict(divisions=(1, 0, 1)), "divisions must be three integers"),
    (dict(abutment_height=0.0), "abutment_height must be a positive"),
])
def test_bad_parameters_name_the_parameter(kw, match):
    args = dict(span=2.0, rise=1.0, thickness=0.2, depth=0.3, n=6, abutment_height=0.4)
    args.update(kw)
    m = Model()
    with pytest.raises(GeometryError, match=match):
        add_arch(m, MAT, **args)
    assert m.n_blocks == 0
