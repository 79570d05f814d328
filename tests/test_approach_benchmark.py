"""benchmarks.approach: its starts, its spot argument, its summary, and one real start end to end."""
import argparse
import math

import numpy as np
import pytest

from benchmarks import approach


@pytest.fixture(scope="module")
def real_world(world_dir):
    from sim.world import load_world

    return load_world("real")


def test_starts_stand_on_true_floor_and_face_the_spot_or_away(real_world):
    spot = approach.SPOTS["east-nook"]
    starts = approach._starts(real_world, spot, (4.0, 8.0), 15.0)
    assert starts and len(starts) % 2 == 0
    truth = real_world.nav_truth > 0
    for r, bearing, x, y, yaw, facing in starts:
        assert truth[int(math.floor(y)), int(math.floor(x))]
        assert math.hypot(x - spot[0], y - spot[1]) == pytest.approx(r)
        toward = math.degrees(math.atan2(spot[1] - y, spot[0] - x)) % 360.0
        off = abs((yaw - toward + 180.0) % 360.0 - 180.0)
        assert off == pytest.approx(0.0 if facing == "toward" else 180.0, abs=1e-6)
    # the rocks south and east of the nook hold no start
    assert all(not (146.0 < x < 155.0 and 102.0 < y < 109.0) for _, _, x, y, _, _ in starts)


def test_spot_argument_takes_a_name_or_four_numbers():
    assert approach._parse_spot("east-nook") == (approach.SPOTS["east-nook"], approach.VIEWS["east-nook"])
    assert approach._parse_spot("10,20,90,3") == ((10.0, 20.0), (90.0, 3.0))
    for bad in ("nowhere", "10,20", "a,b,c,d"):
        with pytest.raises(argparse.ArgumentTypeError):
            approach._parse_spot(bad)


def test_a_spot_with_no_sample_spot_of_the_world_nearby_is_refused(real_world):
    from sim.twin import RoverTwin

    twin = RoverTwin(real_world, seed=0)
    twin.reset(0)
    with pytest.raises(ValueError, match="no sample spot"):
        approach._place_sample(twin, (99.0, 86.0))  # the start, on open floor


def test_summary_counts_per_shadow_setting_and_radius_and_names_the_failures():
    def row(shadows, r, collected, t):
        return dict(shadows=shadows, radius_m=r, bearing_deg=90.0, x=1.0, y=2.0, facing="away",
                    collected=collected, time_s=t, stuck_s=0.5, end=(3.0, 4.0))

    lines = approach.summarise([row("off", 4.0, True, 20.0), row("off", 4.0, False, None),
                                row("on", 4.0, True, 30.0), row("off", 8.0, True, 10.0)])
    assert lines[0].startswith("shadows off r= 4.0 m: collected 1/2, time median 20.0 s")
    assert lines[1].startswith("shadows off r= 8.0 m: collected 1/1")
    assert lines[2].startswith("shadows on  r= 4.0 m: collected 1/1")
    assert sum("not collected" in line for line in lines) == 1
    assert lines[-1] == "collected 3/4 starts"


def test_the_client_collects_the_east_nook_sample_from_its_open_side(real_world):
    """End to end: shown the sample once, moved 6 m west of it (the open side) facing it, the client picks
    it up under Unity timing; the rocks beside the nook are in the twin's physics."""
    spot = approach.SPOTS["east-nook"]
    start = next(s for s in approach._starts(real_world, spot, (6.0,), 15.0) if s[1] == 180.0 and s[5] == "toward")
    row = approach.run_start((start, spot, approach.VIEWS["east-nook"], "off", 60.0))
    assert row["collected"], row
    assert row["time_s"] < 60.0


def test_the_picture_marks_every_start(real_world, tmp_path):
    spot = approach.SPOTS["east-nook"]
    rows = [dict(shadows="off", radius_m=6.0, bearing_deg=180.0, x=spot[0] - 6.0, y=spot[1], facing="toward",
                 collected=True, time_s=15.0, stuck_s=0.2, end=spot),
            dict(shadows="off", radius_m=6.0, bearing_deg=210.0, x=spot[0] - 5.2, y=spot[1] - 3.0, facing="away",
                 collected=False, time_s=None, stuck_s=9.0, end=spot)]
    path = tmp_path / "approach.png"
    approach.draw(rows, spot, path, real_world)
    import cv2

    img = cv2.imread(str(path))
    assert img is not None and img.shape[1] == 2 * 9 * 32
    green = np.all(img == (60, 200, 60), axis=2).sum()
    red = np.all(img == (50, 50, 230), axis=2).sum()
    assert green > 30 and red > 30  # one filled dot of each outcome
