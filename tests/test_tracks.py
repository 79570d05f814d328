"""Tyre tracks (sim/tracks.py): laying rule, the 200-per-wheel cap, drawn behind a moving rover."""
import numpy as np
import pytest

from sim import tracks
from sim.render import Renderer
from sim.tracks import MAX_QUADS_PER_WHEEL, TRIM_BATCH, TyreTracks
from test_render import _flat_world


@pytest.fixture(scope="module")
def flat_renderer():
    return Renderer(_flat_world())


def test_a_wheel_lays_a_quad_only_after_moving_more_than_5_cm():
    t = TyreTracks()
    t.update(100.0, 100.0, 0.0)
    assert t.counts() == (1, 1)  # first rendered frame lays one quad per rear wheel
    for i in range(1, 6):
        t.update(100.0 + 0.04 * i / 5, 100.0, 0.0)  # creeping 4 cm in all
    assert t.counts() == (1, 1)
    t.update(100.06, 100.0, 0.0)
    assert t.counts() == (2, 2)
    left, right = t.wheel_positions(100.0, 100.0, 90.0)  # facing north: left wheel is west
    assert left[0] < 100.0 < right[0] and left[1] == pytest.approx(100.0 - 0.336)


def test_at_most_200_quads_per_wheel_trimmed_50_at_a_time():
    t = TyreTracks()
    for i in range(MAX_QUADS_PER_WHEEL):
        t.update(10.0 + 0.1 * i, 100.0, 0.0)
    assert t.counts() == (MAX_QUADS_PER_WHEEL, MAX_QUADS_PER_WHEEL)
    t.update(10.0 + 0.1 * MAX_QUADS_PER_WHEEL, 100.0, 0.0)
    assert t.counts() == (MAX_QUADS_PER_WHEEL + 1 - TRIM_BATCH,) * 2
    for i in range(1000):
        t.update(40.0 + 0.1 * i, 100.0, 0.0)
        assert max(t.counts()) <= MAX_QUADS_PER_WHEEL
    # the newest quads are kept, the oldest dropped
    assert t.quads[:, 0].max() == pytest.approx(40.0 + 0.1 * 999 - 0.336)
    assert t.quads[:, 0].min() > 40.0 + 0.1 * 800 - 0.336


def test_tracks_show_behind_a_rover_that_turned_back(flat_renderer):
    """Drive 4 m east, turn round: the two tracks lie ahead, darker than the sand (they fail RGB > 160)
    and only where the wheels went."""
    t = TyreTracks()
    for i in range(81):
        t.update(98.0 + 0.05 * i + 0.001, 100.0, 0.0)
    pose = (102.6, 100.0, 180.0, 0.0, 0.0)  # looking back west along the tracks
    plain = flat_renderer.render(pose)
    img = flat_renderer.render(pose, tracks=t)
    assert np.all(plain[100:] > 160)  # bare sand is navigable
    dark = ~np.all(img > 160, axis=2)
    assert dark[100:].sum() > 300
    assert not np.any(img[:80] != plain[:80])  # nothing drawn above the horizon
    # the wheels were 0.395 m either side of the centre line: two stripes, clear centre between them
    row = dark[120]  # ~1.3 m ahead of the camera
    cols = np.nonzero(row)[0]
    assert cols.min() < 120 and cols.max() > 200 and not row[150:171].any()
    # colour: the tinted tread, darker than sand but not black
    rgb = img[dark].astype(float).mean(axis=0)
    assert 90 < rgb[0] < 160 and rgb[0] > rgb[2]
    # a track hidden behind the camera (just laid under the rover) is not drawn
    t2 = TyreTracks()
    t2.update(100.0, 100.0, 0.0)
    assert np.array_equal(flat_renderer.render((100.0, 100.0, 0.0, 0.0, 0.0), tracks=t2),
                          flat_renderer.render((100.0, 100.0, 0.0, 0.0, 0.0)))


def test_twin_lays_tracks_as_it_drives_and_a_reset_clears_them():
    from sim.twin import RoverTwin

    twin = RoverTwin(_flat_world(), seed=0)
    twin.reset(0, start_yaw=0.0)
    for _ in range(40):
        twin.step("data", {"steering_angle": "0", "throttle": "1", "brake": "0"})
    counts = twin._tyre_tracks.counts()
    assert counts[0] > 3 and counts[0] == counts[1]
    twin.reset(0)
    twin.step("data", {"steering_angle": "0", "throttle": "0", "brake": "1"})
    assert twin._tyre_tracks.counts() == (1, 1)


def test_procedural_tread_stands_in_without_the_shared_texture(tmp_path):
    alpha = tracks.load_tread_alpha(tmp_path / "missing.png")
    assert alpha.shape == (128, 128)
    assert 0.3 < (alpha >= 0.5).mean() < 0.55  # about the real texture's 40 % opaque
    mips = tracks.tread_mips(alpha)
    assert mips.shape == (8, 128, 128) and mips.dtype == np.uint8
    assert np.array_equal(mips[0], alpha >= 0.5)


def test_real_tread_texture_is_read_at_run_time(world_dir):
    alpha = tracks.load_tread_alpha()
    assert alpha.shape == (128, 128)
    assert (alpha >= 0.5).mean() == pytest.approx(0.40, abs=0.01)


def test_replay_lays_tracks_between_logged_rows_at_the_render_rate():
    """A log at 15 Hz, 2 m/s east: rows are 0.133 m apart, the simulator rendered (and laid) at 30 Hz,
    so the replay interpolates and lays quads about every 0.067 m; without row times, one per row."""
    rows = 31
    poses = [(100.0 + 2.0 / 15 * i, 100.0, 0.0) for i in range(rows)]
    times = [i / 15 for i in range(rows)]
    with_times = dict(tracks.replay_quads(poses, times))
    without = dict(tracks.replay_quads(poses))
    assert sorted(with_times) == list(range(rows))
    last = with_times[rows - 1]
    assert len(last) == 2 * (2 * (rows - 1) + 1)  # both wheels, every interpolated frame
    assert len(without[rows - 1]) == 2 * rows
    gaps = np.diff(np.sort(last[last[:, 1] > 100.0][:, 0]))
    assert gaps.max() < 0.07
    # only the asked-for rows are yielded; a pause longer than REPLAY_MAX_GAP_S is not bridged
    kept = dict(tracks.replay_quads(poses, times, keep=[5, 9]))
    assert sorted(kept) == [5, 9] and np.array_equal(kept[9], with_times[9])
    paused = dict(tracks.replay_quads([(100.0, 100.0, 0.0), (104.0, 100.0, 0.0)], [0.0, 5.0]))
    assert len(paused[1]) == 4
    # a log whose rows do not all carry a time is replayed as one without times (one update per row)
    partly = dict(tracks.replay_quads(poses, times[:-1] + [None]))
    assert len(partly[rows - 1]) == len(without[rows - 1])


def test_realism_replay_draws_the_tracks_of_the_logged_drive(flat_renderer):
    """sim.realism renders each used frame with the tracks laid along ALL logged rows before it (also the
    rows a stride skips): driving east then looking back west shows them; --tracks off shows bare sand."""
    from pathlib import Path

    from sim import realism

    out = [realism.LoggedFrame(Path(f"f{i}.jpg"), (98.0 + 0.1 * i, 100.0, 0.0, 0.0, 0.0), 2.0, i / 20)
           for i in range(41)]
    out.append(realism.LoggedFrame(Path("back.jpg"), (102.6, 100.0, 180.0, 0.0, 0.0), 0.0, 2.1))
    used = [0, len(out) - 1]  # a stride that skips the whole drive
    laid = realism.replay_tracks(out, used, flat_renderer.world)
    assert sorted(laid) == used and len(laid[used[-1]]) > 100
    img = flat_renderer.render(out[-1].pose, tracks=laid[used[-1]])
    plain = flat_renderer.render(out[-1].pose)
    assert (~np.all(img[100:] > 160, axis=2)).sum() > 300 and np.all(plain[100:] > 160)
