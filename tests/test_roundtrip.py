"""Round trip: analyse segment(phantom(rods)) and the true rods alike; cv_e must agree within 5%."""

import numpy as np
import pytest

from rodwarp import ct
from rodwarp.analysis import compute_fields, field_statistics
from rodwarp.ct import segment_volume


@pytest.mark.slow
def test_segment_of_phantom_gives_the_same_entanglement_statistics():
    shape = (224, 224, 224)
    truth = ct.scene_random_packing(shape, n_rods=100, radius=3.0, aspect=30.0, touching_fraction=0.5, seed=4)
    vol = ct.render_phantom(truth, shape, blur_sigma=1.0, cnr=5.0, seed=4)
    found = segment_volume(vol).rods
    found.contacts = None
    truth = truth.copy()
    # the same domain (the scanned volume), grid, ball and contact rule for both
    box = np.array([[0.0, 0.0, 0.0], [shape[2] - 1.0, shape[1] - 1.0, shape[0] - 1.0]])
    truth.box, found.box = box, box
    truth.contacts = None
    kw = dict(radius=float(np.sqrt(6.0 * 180.0)), contact_tolerance=0.6)
    ft = compute_fields(truth, **kw)
    ff = compute_fields(found, **kw)
    st, sf = field_statistics(ft), field_statistics(ff)
    assert st["n_valid_voxels"] > 50
    assert sf["cv_e"] == pytest.approx(st["cv_e"], rel=0.05)
    assert sf["mean_e"] == pytest.approx(st["mean_e"], rel=0.05)
    assert sf["mean_phi"] == pytest.approx(st["mean_phi"], rel=0.05)
