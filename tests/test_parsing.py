"""Telemetry parsing: every locale/format quirk the simulator can produce, and
garbage that must become a bad frame (never an exception)."""
import base64
import math

import cv2
import numpy as np
import pytest

import supporting_functions as sf
from rover_state import RoverState


def _jpeg(width=320, height=160, seed=0):
    rng = np.random.default_rng(seed)
    img = rng.integers(0, 255, (height, width, 3), dtype=np.uint8)
    ok, buf = cv2.imencode(".jpg", img)
    assert ok
    return buf.tobytes()


def _b64(raw):
    return base64.b64encode(raw).decode("ascii")


def telemetry(locale="en-US", **override):
    """A valid simulator-style telemetry dict (all strings)."""
    n4 = lambda v: sf.format_dotnet_number(v, 4, locale)  # noqa: E731
    n2 = lambda v: sf.format_dotnet_number(v, 2, locale)  # noqa: E731
    data = {
        "steering_angle": n4(-3.5), "throttle": n4(0.2), "brake": n4(0),
        "speed": n4(1.25), "position": f"{n4(99.67)};{n4(85.589)}",
        "pitch": n4(359.5), "yaw": n4(56.8256), "roll": n4(0.75),
        "near_sample": "0", "picking_up": "0", "sample_count": "6",
        "samples_x": ";".join(n2(v) for v in (97.44, 104.56)),
        "samples_y": ";".join(n2(v) for v in (74.65, 80.78)),
        "image": _b64(_jpeg()),
    }
    data.update(override)
    return data


# --- numbers -----------------------------------------------------------------
@pytest.mark.parametrize("text, value", [
    ("0.2000", 0.2), ("1,2345", 1.2345), ("-1,2345", -1.2345),
    ("1.234,5678", 1234.5678), ("1,234.5678", 1234.5678),  # N4 group separators
    ("12.345.678,9000", 12345678.9), ("12,345,678.9000", 12345678.9),
    ("1 234,5678", 1234.5678), ("1\u00a0234,5678", 1234.5678), ("1\u202f234,5", 1234.5),
    ("1'234.5", 1234.5),  # fr-FR / de-CH groups
    ("2.093137E-07", 2.093137e-07), ("2,093137E-07", 2.093137e-07), ("1e3", 1000.0),
    ("\u22121,5", -1.5), ("+3", 3.0), (" 4.5 ", 4.5), (",5", 0.5),
    ("1,234", 1.234),  # a lone separator is the decimal point (N4 always prints decimals)
])
def test_parse_number_locales(text, value):
    assert sf.parse_number(text) == pytest.approx(value)


@pytest.mark.parametrize("text", ["", "abc", "-", ".", "1,2,3", "1.2.3", "1,2.3,4",
                                  "1.23,5", "12a", "e5", None, [], {}, True])
def test_parse_number_garbage_is_none(text):
    assert sf.parse_number(text) is None


def test_parse_number_nan_inf_words_parse_but_are_not_finite():
    assert math.isnan(sf.parse_number("NaN"))
    assert sf.parse_number("Infinity") == math.inf
    assert sf.parse_number("-\u221e") == -math.inf


@pytest.mark.parametrize("value", [0.0, 0.2, -15.0, 1234.5678, -98765.4321, 359.9999])
@pytest.mark.parametrize("locale", ["en-US", "de-DE"])
def test_format_dotnet_number_round_trips(value, locale):
    text = sf.format_dotnet_number(value, 4, locale)
    assert sf.parse_number(text) == pytest.approx(value, abs=1e-4)


def test_parse_number_fast_path_equals_the_general_rules():
    """The plain-number fast path must read every string exactly as the locale rules do (bit for bit)."""
    rng = np.random.default_rng(0)
    values = np.concatenate([rng.uniform(-400, 400, 300), rng.uniform(-2, 2, 100), [0.0, -0.0, 5e-5, -5e-5]])
    texts = ["0", "-0", "007.5", "-0.0000", "12.", ".5", "1e3", "+3", "1_000", " 4.5", "١.5"]
    for v in values:
        for decimals in (2, 4):
            texts += [sf.format_dotnet_number(v, decimals, loc) for loc in ("en-US", "de-DE")]
    for text in texts:
        fast, general = sf.parse_number(text), sf._parse_number_general(text)
        assert (fast is None and general is None) or (
            fast == general and math.copysign(1, fast) == math.copysign(1, general)), text


def test_format_dotnet_number_matches_n4():
    assert sf.format_dotnet_number(1234.56789, 4, "en-US") == "1,234.5679"
    assert sf.format_dotnet_number(1234.56789, 4, "de-DE") == "1.234,5679"
    assert sf.format_dotnet_number(0.5, 2, "de-DE") == "0,50"


@pytest.mark.parametrize("deg, signed", [(359.5, -0.5), (0.25, 0.25), (180.0, 180.0),
                                         (180.5, -179.5), (360.0, 0.0), (-1.0, -1.0)])
def test_signed_angle(deg, signed):
    assert sf.signed_angle(deg) == pytest.approx(signed)


# --- whole frames ------------------------------------------------------------
@pytest.mark.parametrize("locale", ["en-US", "de-DE"])
def test_valid_frame(locale):
    tel = sf.parse_telemetry(telemetry(locale))
    assert tel.ok, tel.warnings
    assert tel.warnings == []
    assert tel.speed == pytest.approx(1.25)
    assert tel.pos == pytest.approx((99.67, 85.589))
    assert tel.pitch == pytest.approx(-0.5)  # 359.5 -> signed
    assert tel.roll == pytest.approx(0.75)
    assert tel.yaw == pytest.approx(56.8256)
    assert tel.steer == pytest.approx(-3.5)
    assert tel.sample_count == 6
    assert tel.samples_xy.shape == (2, 2)
    assert tel.samples_xy[1] == pytest.approx((104.56, 80.78))
    assert tel.image.shape == (160, 320, 3) and tel.image.dtype == np.uint8
    assert tel.image_jpeg == base64.b64decode(telemetry()["image"])
    assert tel.sim_time is None
    assert not tel.near_sample and not tel.picking_up


def test_group_separator_positions():
    tel = sf.parse_telemetry(telemetry(position="1.234,5000;85,5890"))
    assert tel.ok and tel.pos == pytest.approx((1234.5, 85.589))


def test_scientific_values():
    tel = sf.parse_telemetry(telemetry(roll="2.093137E-07", speed="-1,5E-03"))
    assert tel.ok
    assert tel.roll == pytest.approx(2.093137e-07)
    assert tel.speed == pytest.approx(-1.5e-3)


def test_empty_sample_lists():
    tel = sf.parse_telemetry(telemetry(samples_x="", samples_y="", sample_count="0"))
    assert tel.ok and tel.samples_xy.shape == (0, 2) and tel.sample_count == 0


def test_mismatched_sample_lists_are_truncated_with_warning():
    tel = sf.parse_telemetry(telemetry(samples_x="1.00;2.00;3.00", samples_y="4.00;5.00"))
    assert tel.ok and tel.samples_xy.shape == (2, 2) and tel.warnings


def test_garbage_sample_list_is_ignored_not_fatal():
    tel = sf.parse_telemetry(telemetry(samples_x="1.00;zz", samples_y="4.00;5.00"))
    assert tel.ok and tel.samples_xy.shape == (0, 2) and tel.warnings


@pytest.mark.parametrize("key", ["speed", "position", "yaw", "pitch", "roll", "image"])
def test_missing_essential_field_is_a_bad_frame(key):
    data = telemetry()
    del data[key]
    tel = sf.parse_telemetry(data)
    assert not tel.ok and any(key in w for w in tel.warnings)


@pytest.mark.parametrize("key", ["steering_angle", "throttle", "brake", "sample_count",
                                 "near_sample", "samples_x"])
def test_missing_optional_field_defaults(key):
    data = telemetry()
    del data[key]
    tel = sf.parse_telemetry(data)
    assert tel.ok


@pytest.mark.parametrize("key, value", [
    ("speed", "NaN"), ("speed", "Infinity"), ("speed", "-\u221e"), ("speed", "fast"),
    ("speed", "1e9"), ("yaw", "x"), ("pitch", ""), ("position", "99.0"),
    ("position", "a;b"), ("position", "NaN;1.0"), ("position", 5), ("speed", None),
    ("image", "not base64 !!"), ("image", ""), ("image", _b64(b"\xff\xd8garbage")),
    ("image", 123),
])
def test_bad_essential_value_is_a_bad_frame(key, value):
    tel = sf.parse_telemetry(telemetry(**{key: value}))
    assert not tel.ok and tel.warnings


def test_unreadable_picking_up_blocks_pickup():
    tel = sf.parse_telemetry(telemetry(picking_up="??", near_sample="1"))
    assert tel.ok and tel.picking_up and tel.near_sample


def test_numbers_sent_as_json_numbers_are_tolerated():
    tel = sf.parse_telemetry(telemetry(speed=1.5, yaw=90))
    assert tel.ok and tel.speed == 1.5 and tel.yaw == 90.0


@pytest.mark.parametrize("data", [None, "telemetry", 42, [1, 2], {"foo": "bar"}])
def test_not_a_telemetry_object(data):
    tel = sf.parse_telemetry(data)
    assert not tel.ok and tel.warnings


def test_yaw_wraps_into_0_360():
    assert sf.parse_telemetry(telemetry(yaw="360.0000")).yaw == pytest.approx(0.0)
    assert sf.parse_telemetry(telemetry(yaw="-10.0000")).yaw == pytest.approx(350.0)


def test_sim_time_is_read_when_present():
    tel = sf.parse_telemetry(telemetry(sim_time="12.5000"))
    assert tel.ok and tel.sim_time == pytest.approx(12.5)


# --- images ------------------------------------------------------------------
def test_image_with_same_aspect_is_resized():
    tel = sf.parse_telemetry(telemetry(image=_b64(_jpeg(640, 320))))
    assert tel.ok and tel.image.shape == (160, 320, 3)
    assert any("resized" in w for w in tel.warnings)


def test_image_with_other_aspect_is_rejected():
    tel = sf.parse_telemetry(telemetry(image=_b64(_jpeg(320, 240))))
    assert not tel.ok and any("rejected" in w for w in tel.warnings)


def test_decode_image_returns_rgb():
    bgr = np.zeros((160, 320, 3), np.uint8)
    bgr[:, :, 2] = 255  # red in BGR
    ok, buf = cv2.imencode(".png", bgr)
    rgb = sf.decode_image(_b64(buf.tobytes()))
    assert rgb.shape == (160, 320, 3) and rgb[0, 0, 0] == 255 and rgb[0, 0, 2] == 0


def test_decoded_frames_equal_bgr_decode_plus_colour_conversion(test_dataset_dir):
    """Decoding straight to RGB (one pass less) gives exactly the pixels of BGR decode + cvtColor."""
    paths = sorted((test_dataset_dir / "IMG").glob("*.jpg"))[::10]
    assert paths
    for path in paths:
        raw = path.read_bytes()
        ref = cv2.cvtColor(cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        assert np.array_equal(sf.decode_image(_b64(raw)), ref)


def test_simplejpeg_decodes_plain_jpegs_to_the_pixels_opencv_gives(monkeypatch):
    """The fast decoder is taken for plain JPEGs (4:2:0 and 4:4:4, several qualities) and gives OpenCV's pixels;
    a truncated JPEG is None either way."""
    simplejpeg = pytest.importorskip("simplejpeg")
    calls = []
    real = simplejpeg.decode_jpeg
    monkeypatch.setattr(sf._simplejpeg, "decode_jpeg", lambda *a, **k: calls.append(1) or real(*a, **k))
    rng = np.random.default_rng(3)
    smooth = cv2.GaussianBlur(rng.integers(0, 255, (160, 320, 3), dtype=np.uint8), (9, 9), 3)
    for img in (smooth, rng.integers(0, 255, (160, 320, 3), dtype=np.uint8)):
        for quality, sampling in ((75, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420), (95, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444)):
            raw = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, quality,
                                             cv2.IMWRITE_JPEG_SAMPLING_FACTOR, sampling])[1].tobytes()
            fast = sf._decode_jpeg_bytes(raw)
            monkeypatch.setattr(sf, "USE_SIMPLEJPEG", False)
            assert np.array_equal(fast, sf._decode_jpeg_bytes(raw))
            monkeypatch.setattr(sf, "USE_SIMPLEJPEG", True)
    assert len(calls) == 4
    assert sf._decode_jpeg_bytes(raw[: len(raw) // 2]) is None


def test_repeated_sample_strings_parse_to_fresh_equal_arrays_and_bad_ones_warn_each_time():
    data = {"samples_x": "97.44;104.56", "samples_y": "74.65;80.78"}
    first = sf._parse_samples(data, [])
    first[0, 0] = -1.0  # a caller scribbling on its array must not change the next frame's
    again = sf._parse_samples(dict(data), [])
    assert again.tolist() == [[97.44, 74.65], [104.56, 80.78]]
    assert sf._parse_samples({"samples_x": "97.44", "samples_y": "74.65"}, []).tolist() == [[97.44, 74.65]]
    for _ in range(2):
        warnings = []
        assert sf._parse_samples({"samples_x": "1;x", "samples_y": "2;3"}, warnings).shape == (0, 2)
        assert warnings


@pytest.mark.parametrize("b64", [None, "", "%%%", _b64(b"hello"), 7])
def test_decode_image_garbage_is_none(b64):
    assert sf.decode_image(b64) is None


def test_decode_image_tolerates_data_prefix():
    assert sf.decode_image("data:image/jpeg;base64," + _b64(_jpeg())) is not None


# --- rover update ------------------------------------------------------------
def test_update_rover_first_valid_frame_sets_start():
    rover = RoverState()
    sf.update_rover(rover, sf.parse_telemetry({"speed": "x"}), 5.0)
    assert rover.start_time is None and not rover.telemetry_ok and rover.frame_count == 1
    sf.update_rover(rover, sf.parse_telemetry(telemetry()), 10.0)
    assert rover.start_time == 10.0 and rover.total_time == 0.0
    assert rover.start_pos == pytest.approx((99.67, 85.589))
    assert rover.samples_initial == 6
    sf.update_rover(rover, sf.parse_telemetry(telemetry(sample_count="5",
                                                       position="50.0000;60.0000")), 12.5)
    assert rover.total_time == pytest.approx(2.5)
    assert rover.samples_initial == 6 and rover.samples_remaining == 5
    assert rover.start_pos == pytest.approx((99.67, 85.589))
    assert rover.pos == pytest.approx((50.0, 60.0))
    assert rover.vel == pytest.approx(1.25) and rover.pitch == pytest.approx(-0.5)
    assert rover.img.shape == (160, 320, 3)
    assert len(rover.samples_pos[0]) == 2
