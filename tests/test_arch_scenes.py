"""The arch and dry-wall scenes (cases/arch.py, cases/dry_wall.py) against limit analysis: the
thrust-line LP of tests/limit_analysis.py for the arch (minimum thickness, tilting factor, hinges)
and rigid-block statics for the block (tan(theta) = b/h or mu). Each run is a few seconds."""
import numpy as np
import pytest

import limit_analysis as la
from dr_masonry.cases import arch, dry_wall

N = 12


def _arch(tmp_path, **kw):
    params = dict(arch.PARAMS, out=str(tmp_path / "arch"), **kw)
    sim, a, res, found = arch.run(params)
    sim.close()
    return res, found


def test_arch_stands_above_and_collapses_below_its_minimum_thickness(tmp_path):
    """Stable at 1.03 t_min, collapsing under its own weight at 0.97 t_min (the LP's t_min of the
    same 12 voussoirs, t/R = 0.1049), with the LP's five-hinge mechanism."""
    lp = la.minimum_thickness(1.0, N)
    above, _ = _arch(tmp_path, thickness=1.03 * lp.value, load="gravity")
    assert not above.collapsed
    below, (hinges, faces, _) = _arch(tmp_path, thickness=0.97 * lp.value, load="gravity")
    assert below.collapsed and below.stage == "gravity"
    assert "did not converge" in below.message
    assert hinges == lp.hinges and faces == lp.faces


@pytest.mark.parametrize("t_R", [0.15, 0.2])
def test_tilting_factor_and_hinges_match_the_lp(tmp_path, t_R):
    """The collapse factor is bracketed by the last converged row and the failed attempt, both
    within 3 % of the LP's (n = 12: 0.1573 at t/R = 0.15, 0.2852 at 0.2); the failed attempt
    hinges at the LP's four joints, on the LP's faces."""
    lp = la.collapse_factor(1.0, t_R, N)
    res, (hinges, faces, _) = _arch(tmp_path, thickness=t_R)
    assert res.collapsed and res.stage == "tilt"
    assert res.factor < res.failed
    assert res.factor == pytest.approx(lp.value, rel=0.03)
    assert res.failed == pytest.approx(lp.value, rel=0.03)
    # the factor from the abutments' reaction balances the applied one
    np.testing.assert_allclose(res.reaction[2:], res.factors[2:], atol=2e-3 * lp.value + 1e-4)
    assert hinges == lp.hinges and faces == lp.faces


def _block(tmp_path, **kw):
    params = dict(dry_wall.PARAMS, out=str(tmp_path / "block"), **kw)
    sim, blocks, base, res, how = dry_wall.run(params)
    sim.close()
    return res, how, dry_wall.closed_form(params)


def test_slender_block_overturns_at_b_over_h(tmp_path):
    res, how, (ref, ref_mode) = _block(tmp_path, width=0.2, height=0.4, mu=0.8)
    assert (ref, ref_mode) == (0.5, "overturns") and how == "overturns"
    assert 0.49 <= res.factor < res.failed and 0.50 <= res.failed <= 0.55


def test_squat_block_slides_at_mu(tmp_path):
    res, how, (ref, ref_mode) = _block(tmp_path, width=0.4, height=0.2, mu=0.4)
    assert (ref, ref_mode) == (0.4, "slides") and how == "slides"
    assert 0.39 <= res.factor < res.failed <= 0.41


def test_stack_of_three_overturns_as_one_block(tmp_path):
    """Three dry blocks 0.3 x 0.2 m: the base joint governs, lam = b / H = 0.5."""
    res, how, (ref, _) = _block(tmp_path, width=0.3, height=0.2, courses=3, mu=0.8)
    assert how == "overturns" and ref == pytest.approx(0.5)
    assert 0.49 <= res.factor < res.failed <= 0.51


def test_a_block_on_a_wider_coarser_base_rocks_about_the_base_nodes(tmp_path):
    """The contact points are the slave face's nodes (the finer mesh: here the base's, at
    x = -0.1, 0.0333, 0.1667, 0.3 m): the 0.2 m block rocks about the outermost one under it,
    x = 0.1667, so lam = (0.1667 - 0.1) / (h / 2) = 1/3, not b / h = 0.5."""
    res, how, _ = _block(tmp_path, width=0.2, height=0.4, mu=0.8, base_overhang=0.1, base_nx=3)
    assert how == "overturns"
    assert res.factor < 1 / 3 <= res.failed <= 1 / 3 + 0.01
    assert res.factor >= 1 / 3 - 0.01


@pytest.mark.parametrize("scene, kw, match", [
    (arch, dict(thickness=1.5), "thickness=1.5: must be in"),
    (arch, dict(load="wind"), "load='wind': valid values"),
    (arch, dict(step=0.0), "step=0.0, lam_max=0.6"),
    (dry_wall, dict(courses=0), "courses=0: must be an integer"),
    (dry_wall, dict(base_overhang=-0.1), "base_overhang=-0.1"),
])
def test_bad_parameters_are_named(scene, kw, match):
    from dr_masonry.params import ParameterError
    with pytest.raises(ParameterError, match=match):
        scene.build(dict(scene.PARAMS, **kw))
