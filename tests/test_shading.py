"""Look terms for the real drives recorded without cast shadows (sim/shading.py)."""
import numpy as np

from sim import shading
from sim.render import Renderer, _darkening_lut
from sim.world import with_shadows
from test_render import _flat_world


def test_shadowless_floor_keeps_its_brightness_near_and_darkens_far():
    d = np.array([0.0, 2.0, 5.0, 10.0, 25.0, 60.0])
    f = shading.shadowless_darkening(d)
    assert f[0] == 1.0 and f[2] > 0.93  # the near floor loses at most a few per cent (as measured: 0.95)
    assert f[3] < f[2] - 0.15 and 0.6 < f[3] < 0.85 and f[4] < 0.6  # beyond the 5.2 m knee it falls fast
    assert np.all(np.diff(f) <= 0)
    assert 0.9 * min(shading.SHADOWLESS_FAR_RGB) <= f[-1] < max(shading.SHADOWLESS_FAR_RGB)
    # far away the floor turns redder: green / red falls (the client's shadowed-sand rule needs >= 0.9)
    red, green = shading.shadowless_darkening(d, 0), shading.shadowless_darkening(d, 1)
    assert np.allclose(red[:3], green[:3]) and green[-1] / red[-1] < 0.95
    tint = shading.far_tint_lut()
    assert np.allclose(tint[:, 1], 1.0) and tint[-1, 0] > 1.0 > tint[-1, 2]
    # the quality level with cast shadows (test_dataset) darkens much less far away
    lit, shadowless = _darkening_lut(True), _darkening_lut(False)
    assert shadowless[-1] < lit[-1] - 0.2


def test_twin_without_shadows_renders_the_far_floor_darker_not_the_near_floor():
    """On level sand the rows near the horizon (floor > 10 m away) fail the starter threshold without
    shadows (as on megalphian / royalejandro), while the floor within the knee keeps nearly its colour."""
    world = _flat_world()
    pose = (100.0, 100.0, 0.0, 0.0, 0.0)
    off = Renderer(with_shadows(world, False)).render(pose)
    on = Renderer(with_shadows(world, True)).render(pose)
    assert np.all(np.abs(off[100:].astype(int) - on[100:]) <= 8)  # floor within 4 m: nearly as lit
    far_rows = slice(80, 82)  # just under the horizon: floor more than 10 m away
    assert np.all(on[far_rows] > 160)
    assert not np.all(off[far_rows] > 160, axis=2).any()
    g_per_r = off[far_rows, :, 1].astype(float) / off[far_rows, :, 0]
    assert np.all(g_per_r < on[far_rows, :, 1].astype(float) / on[far_rows, :, 0])
