"""The spot view table the client ships is what the twin's camera shows: re-rendered for two spots and compared."""
import json

import numpy as np
import pytest

from navigation import sample_spots
from sim import spot_views as V


@pytest.fixture(scope="module")
def real_worlds(world_dir):
    from sim.world import load_real_world, with_shadows

    world = load_real_world(world_dir)
    return [with_shadows(world, False), with_shadows(world, True)]


def _spot_index(xy):
    return int(np.argmin(np.hypot(*(sample_spots.CANYON_SPOTS - xy).T)))


@pytest.mark.parametrize("xy", [(148.78, 109.56), (21.72, 102.18)])  # the east nook (few views) and the west tip (many)
def test_the_shipped_table_is_what_the_twin_shows(real_worlds, xy):
    k = _spot_index(xy)
    table = V.spot_view_table(real_worlds, sample_spots.CANYON_SPOTS[k:k + 1], progress=False)
    shipped = sample_spots.load_views()
    assert shipped is not None
    assert np.array_equal(table[0], shipped.px[k]), "navigation/spot_views.json is stale: run python -m sim.spot_views"


def test_stands_are_floor_clear_of_rocks(real_worlds):
    world = real_worlds[0]
    assert V.stand_ok(world, 99.67, 85.589)  # the start
    assert not V.stand_ok(world, 5.0, 5.0)  # outside the canyon: raised ground
    assert not V.stand_ok(world, -1.0, 50.0) and not V.stand_ok(world, 50.0, 250.0)


def test_the_json_round_trips_through_the_clients_loader(tmp_path):
    px = np.full((len(sample_spots.CANYON_SPOTS), 36, len(V.RANGES_M)), -1, np.int16)
    px[3, 5, :2] = (25, 9)
    path = tmp_path / "views.json"
    path.write_text(json.dumps(V.to_json(sample_spots.CANYON_SPOTS, px)))
    views = sample_spots.load_views(path)
    assert views is not None and np.array_equal(views.px, px)
    assert views.px_at([3], 50.0, 2.5)[0] == 9 and views.px_at([3], 50.0, 9.0)[0] == 0
