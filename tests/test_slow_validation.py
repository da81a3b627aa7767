"""Long validation runs (``python -m pytest -m slow``): minutes each on 2 cores."""
import pytest

from dr_masonry.cases import squat_wall


@pytest.mark.slow
def test_squat_wall_sensitivity_ordering():
    """Paper Fig. 18 (COMP-6 monotonic to 10 mm): PAR_B (c, delta_k doubled) clearly raises the
    peak; PAR_A (ft, u_k) and PAR_D (block compression) barely change it. Coarse mesh, about
    10 min. (PAR_C and PAR_E take much longer on this mesh and are not checked yet.)"""
    peaks = {}
    for v in ("reference", "PAR_A", "PAR_B", "PAR_D"):
        params = dict(squat_wall.PARAMS, variant=v, drift=10e-3 / 2.75 * 100, increments=20, h5=None)
        sim, hist, push = squat_wall.run(params, squat_wall.S5)
        peaks[v] = hist["beam.fx"][push].max()
    ref = peaks["reference"]
    assert peaks["PAR_B"] > 1.15 * ref
    assert abs(peaks["PAR_A"] / ref - 1) < 0.10 and abs(peaks["PAR_D"] / ref - 1) < 0.10
