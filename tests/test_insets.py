"""Inset images: valid JPEG base64 of the expected sizes, the 'n/a' path
without ground truth, and metrics computed against the ground truth."""
import base64

import cv2
import numpy as np
import pytest

import supporting_functions as sf
from evaluation.metrics import score_map
from rover_state import RoverState


def _decode(b64):
    assert isinstance(b64, str) and not b64.startswith("data:")
    raw = base64.b64decode(b64, validate=True)
    assert raw[:2] == b"\xff\xd8", "not a JPEG"
    img = cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_COLOR)
    assert img is not None
    return img


def _rover(truth=None):
    r = RoverState(ground_truth=truth)
    r.pos = (100.0, 85.0)
    r.total_time = 12.3
    r.samples_initial, r.samples_remaining = 6, 5
    r.samples_pos = (np.array([97.44, 104.56]), np.array([74.65, 80.78]))
    r.mode, r.target = "forward", (120.5, 90.25)
    return r


def test_insets_decode_to_expected_sizes_without_truth():
    r = _rover()
    one, two = sf.create_output_images(r)
    assert _decode(one).shape == (200 * sf.INSET1_SCALE, 200 * sf.INSET1_SCALE, 3)
    assert _decode(two).shape == (160, 320, 3)


def test_text_reads_na_without_truth():
    r = _rover()
    score = score_map(r.worldmap, None, [])
    lines = sf.inset_text_lines(r, score)
    assert lines[1] == "Mapped: n/a" and lines[2] == "Fidelity: n/a"
    assert lines[4] == "Collected: 1"
    assert lines[0].startswith("Time: 12.3")


def test_collected_na_before_any_sample_count():
    r = RoverState()
    lines = sf.inset_text_lines(r, score_map(r.worldmap, None, []))
    assert lines[4] == "Collected: n/a"


def test_metrics_with_truth_are_computed():
    truth = np.zeros((200, 200), np.uint8)
    truth[80:90, 90:110] = 255  # 200 navigable cells
    r = _rover(truth)
    r.worldmap[80:90, 90:100, 2] = 255  # 100 good cells
    r.worldmap[50:60, 50:60, 2] = 255  # 100 wrong cells
    r.worldmap[75, 98, 1] = 255  # rock next to sample (97.44, 74.65)
    score = score_map(r.worldmap, truth, [(97.44, 74.65), (104.56, 80.78)])
    lines = sf.inset_text_lines(r, score)
    assert lines[1] == "Mapped: 50.0%" and lines[2] == "Fidelity: 50.0%"
    assert lines[3] == "Located: 1"
    one, two = sf.create_output_images(r)
    assert _decode(one).shape[:2] == (200, 200)


def test_map_inset_is_north_up():
    r = _rover()
    r.samples_pos = (np.zeros(0), np.zeros(0))
    r.pos = (float("nan"), float("nan"))
    r.worldmap[190:195, 100:105, 2] = 255  # navigable far north (y = 190)
    img = sf.render_map_inset(r)
    # north (large y) must be near the top of the displayed image
    assert img[200 - 195:200 - 190, 100:105, 0].mean() > 200  # blue channel in BGR
    assert img[190:195, 100:105, 0].mean() < 50


def test_located_keeps_collected_samples():
    """The starter scores 'located' over the initial samples: a sample that was
    picked up (and vanished from telemetry) keeps counting."""
    r = _rover()
    r.worldmap[75, 97, 1] = 255
    sf.create_output_images(r)  # remembers both samples
    r.samples_pos = (np.array([104.56]), np.array([80.78]))  # first one collected
    mem = r.inset_memory
    assert len(mem.samples_all) == 2


def test_map_inset_is_cached_between_renders():
    r = _rover()
    first, _ = sf.create_output_images(r)
    r.worldmap[:, :, 2] = 255  # change the map: the cache is still sent ...
    for _ in range(sf.INSET1_EVERY_N_FRAMES - 1):
        again, _ = sf.create_output_images(r)
        assert again == first
    fresh, _ = sf.create_output_images(r)  # ... until the N-th frame re-renders
    assert fresh != first


@pytest.mark.parametrize("vision", [None, np.zeros((10, 10, 3), np.uint8),
                                    np.zeros((160, 320, 3), np.float32)])
def test_bad_vision_image_does_not_crash(vision):
    r = _rover()
    r.vision_image = vision
    r.target = "weird"
    _, two = sf.create_output_images(r)
    assert _decode(two).shape == (160, 320, 3)


def test_insets_with_real_ground_truth(ground_truth):
    r = _rover(ground_truth)
    r.worldmap[ground_truth > 0, 2] = 255  # a perfect map
    score = score_map(r.worldmap, ground_truth, [])
    assert score.mapped_pct == pytest.approx(100.0) and score.fidelity_pct == pytest.approx(100.0)
    lines = sf.inset_text_lines(r, score)
    assert lines[1] == "Mapped: 100.0%" and lines[2] == "Fidelity: 100.0%"
    one, _ = sf.create_output_images(r)
    assert _decode(one).shape == (200, 200, 3)
