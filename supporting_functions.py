"""Telemetry parsing and the two inset images sent back to the simulator.

Why so defensive: the simulator formats every number with the host's locale
(.NET ``N4``: ``"1,2345"`` on de-DE, ``"1,234.5678"`` on en-US above 1000),
pitch/roll arrive as raw 0..360 Unity angles, and a single exception in the
server would stall the simulator's lockstep for good.  So parsing never
raises: it returns a :class:`Telemetry` with ``ok`` and a list of warnings,
and the caller answers a bad frame with a safe stop.

Image size rule (documented choice): the camera model assumes 320x160.  A
frame with the same 2:1 aspect (a scaled render of the same field of view) is
resized to 320x160 with a warning; any other size is rejected (bad frame),
because warping it with the 320x160 camera model would map garbage.

Insets: inset 1 is the world map drawn over the ground truth with the
starter's score text, flipped north-up for display; inset 2 is
``rover.vision_image`` with the decision mode and target.  Both are JPEG,
base64, without a ``data:`` prefix.  Inset 1 is re-rendered only every
``INSET1_EVERY_N_FRAMES`` frames to stay inside the per-frame time budget.
"""
from __future__ import annotations

import base64
import binascii
import logging
import math
import re
from dataclasses import dataclass, field
from typing import List, Optional, Tuple

import cv2
import numpy as np

from evaluation.metrics import score_map
from rover_state import IMAGE_SHAPE, WORLD_SIZE

log = logging.getLogger(__name__)

# --- parsing ---------------------------------------------------------------
MAX_IMAGE_B64_CHARS = 4_000_000  # larger image strings are rejected unread, characters
LIST_SEPARATOR = ";"  # simulator csvSeparatorChar for position and sample lists
MAX_ABS_COORD = 1.0e4  # |position| beyond this is garbage, metres
MAX_ABS_SPEED = 50.0  # |speed| beyond this is garbage, m/s (sim clamps at 5)

# --- insets ----------------------------------------------------------------
INSET_JPEG_QUALITY = 70  # JPEG quality of both insets, 0..100
INSET1_EVERY_N_FRAMES = 5  # re-render the map inset every N frames, else resend the cache
INSET1_SCALE = 1  # map inset pixels per metre (200 px at 1)
INSET_FONT_SCALE = 0.35  # cv2 Hershey font scale for inset text
INSET_LINE_PX = 11  # vertical spacing of inset text lines, px
TRUTH_GREY = 70  # brightness of ground-truth navigable cells under the map, 0..255
SAMPLE_MARK_RADIUS_PX = 2  # radius of the white true-sample marks, px
ROVER_MARK_RADIUS_PX = 2  # radius of the rover position mark, px

_NUMBER_RE = re.compile(r"([+-]?)([0-9.,]*)(?:[eE]([+-]?[0-9]+))?")
_IGNORED_CHARS = re.compile("[\\s\u00a0\u202f\u2009']")  # group separators of other locales
_SPECIAL = {"nan": math.nan, "inf": math.inf, "infinity": math.inf, "\u221e": math.inf}
# the common case, a plain en-US N4/N2 number without group separators ("-12.3456"): float() reads it
# exactly as the general rules below would, at a tenth of their cost (21 numbers per telemetry frame)
_PLAIN_NUMBER_RE = re.compile(r"-?[0-9]+(?:\.[0-9]+)?")


def parse_number(text) -> Optional[float]:
    """A .NET-formatted number in any common locale, or None when unreadable.

    Handles ``"1,2345"`` (comma decimal), ``"1.234,5678"`` (de-DE groups),
    ``"1,234.5678"`` (en-US groups), ``"1 234,5678"`` (fr-FR), ``"1'234.5"``
    (de-CH), ``"2.093137E-07"``, the Unicode minus, and NaN/Infinity words
    (returned as nan/inf so the caller can reject them).  When both ``,`` and
    ``.`` appear the last one is the decimal point.  A single lone separator is
    the decimal point: ``N4`` always prints decimals, so ``"1,234"`` can only
    mean 1.234.
    """
    if isinstance(text, str) and _PLAIN_NUMBER_RE.fullmatch(text):
        return float(text)
    return _parse_number_general(text)


def _parse_number_general(text) -> Optional[float]:
    """parse_number without its fast path (every locale rule; tests compare the two)."""
    if isinstance(text, bool):
        return None
    if isinstance(text, (int, float)):  # the simulator never sends numbers, a twin might
        return float(text)
    if not isinstance(text, str):
        return None
    s = _IGNORED_CHARS.sub("", text.replace("\u2212", "-"))
    if not s:
        return None
    word = s.lstrip("+-").lower()
    if word in _SPECIAL:
        value = _SPECIAL[word]
        return -value if s.startswith("-") else value
    m = _NUMBER_RE.fullmatch(s)
    if m is None:
        return None
    sign, mant, exp = m.groups()
    n_comma, n_dot = mant.count(","), mant.count(".")
    if n_comma and n_dot:
        dec = "," if mant.rfind(",") > mant.rfind(".") else "."
        group = "." if dec == "," else ","
        int_part, _, frac = mant.rpartition(dec)
        if group in frac or not _groups_ok(int_part, group):
            return None
        mant = int_part.replace(group, "") + "." + frac
    elif n_comma > 1 or n_dot > 1:  # only group separators, no decimals
        group = "," if n_comma else "."
        if not _groups_ok(mant, group):
            return None
        mant = mant.replace(group, "")
    elif n_comma:
        mant = mant.replace(",", ".")
    if not any(c.isdigit() for c in mant):
        return None
    try:
        return float(sign + mant + ("e" + exp if exp else ""))
    except ValueError:
        return None


def _groups_ok(int_part: str, group: str) -> bool:
    """Digit groups after the first must have exactly three digits ("1.234.567")."""
    parts = int_part.split(group)
    return all(len(p) == 3 for p in parts[1:]) and len(parts[0]) <= 3 if len(parts) > 1 else True


def format_dotnet_number(value: float, decimals: int = 4, locale: str = "en-US") -> str:
    """``value.ToString("N<decimals>")`` as the simulator prints it on en-US or de-DE.

    The inverse of :func:`parse_number`; tests, benchmarks and the twin use it to
    build telemetry exactly as the simulator does.
    """
    text = f"{float(value):,.{decimals}f}"  # en-US: ',' groups, '.' decimal
    if locale.lower().startswith("de"):
        text = text.replace(",", "\0").replace(".", ",").replace("\0", ".")
    return text


def signed_angle(deg: float) -> float:
    """A 0..360 Unity angle as signed degrees in (-180, 180] (359.5 -> -0.5)."""
    a = math.fmod(deg, 360.0)
    if a > 180.0:
        a -= 360.0
    elif a <= -180.0:
        a += 360.0
    return a


def decode_image(b64) -> Optional[np.ndarray]:
    """Base64 JPEG/PNG -> RGB uint8 (H, W, 3), or None when it does not decode."""
    raw = _b64_to_bytes(b64)
    return None if raw is None else _decode_jpeg_bytes(raw)


def _b64_to_bytes(b64) -> Optional[bytes]:
    if not isinstance(b64, str) or not b64 or len(b64) > MAX_IMAGE_B64_CHARS:
        return None
    if b64.startswith("data:"):  # tolerate a data-URL prefix the simulator never sends
        b64 = b64.partition(",")[2]
    try:
        raw = base64.b64decode(b64, validate=False)
    except (binascii.Error, ValueError):
        return None
    return raw or None


# OpenCV >= 4.10 decodes straight to RGB (the same pixels as BGR + cvtColor, one pass less); older: None
_IMREAD_RGB = getattr(cv2, "IMREAD_COLOR_RGB", None)
try:  # libjpeg-turbo without OpenCV's per-call overhead: the same pixels, 35-40 % less time per frame
    import simplejpeg as _simplejpeg
except ImportError:  # optional: OpenCV decodes everything when it is missing
    _simplejpeg = None
_JPEG_SOI = b"\xff\xd8"  # a JPEG file's first two bytes
_EXIF = b"Exif\x00\x00"  # an EXIF block may rotate the image: OpenCV applies its orientation, simplejpeg does not
USE_SIMPLEJPEG = True  # False: OpenCV decodes every frame (the reference path, tests/test_parsing.py)


def _decode_jpeg_bytes(raw: bytes) -> Optional[np.ndarray]:
    """RGB uint8 (H, W, 3) of JPEG (or PNG, ...) bytes, or None.

    Plain JPEGs (the simulator's) go through simplejpeg when it is installed: libjpeg-turbo with the same
    settings as OpenCV's decoder (accurate integer IDCT, smooth chroma upsampling), so the pixels are the
    same (checked on all 14,399 frames of ../shared and a twin mission, tests/test_parsing.py) at
    ~0.08-0.12 ms instead of ~0.12-0.22 ms. Anything simplejpeg declines goes to OpenCV."""
    if _simplejpeg is not None and USE_SIMPLEJPEG and raw[:2] == _JPEG_SOI and _EXIF not in raw:
        try:
            img = _simplejpeg.decode_jpeg(raw, colorspace="RGB", fastdct=False, fastupsample=False)
        except ValueError:
            img = None
        if img is not None and img.ndim == 3 and img.shape[2] == 3:
            return img
    return _decode_with_opencv(raw)


def _decode_with_opencv(raw: bytes) -> Optional[np.ndarray]:
    buf = np.frombuffer(raw, dtype=np.uint8)
    try:
        img = cv2.imdecode(buf, cv2.IMREAD_COLOR if _IMREAD_RGB is None else _IMREAD_RGB)
    except cv2.error:
        return None
    if img is None or img.ndim != 3 or img.shape[2] != 3:
        return None
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB) if _IMREAD_RGB is None else img


@dataclass
class Telemetry:
    """One parsed telemetry frame.  ``ok`` False means: answer a safe stop."""
    ok: bool = False
    warnings: List[str] = field(default_factory=list)
    steer: float = 0.0  # echoed steering, degrees
    throttle: float = 0.0  # echoed throttle
    brake: float = 0.0  # echoed brake
    speed: float = 0.0  # m/s, negative reversing
    pos: Tuple[float, float] = (math.nan, math.nan)  # world metres
    yaw: float = 0.0  # degrees [0, 360)
    pitch: float = 0.0  # signed degrees, positive = nose down
    roll: float = 0.0  # signed degrees
    near_sample: bool = False
    picking_up: bool = False
    sample_count: Optional[int] = None  # samples remaining
    samples_xy: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # remaining samples
    image: Optional[np.ndarray] = None  # RGB uint8 160x320x3
    image_jpeg: Optional[bytes] = None  # the image bytes exactly as received (recording)
    sim_time: Optional[float] = None  # twin-only clock, seconds


def _number_field(data, key, warnings, default=None):
    """A finite float from ``data[key]``, or ``default`` with a warning."""
    if key not in data:
        warnings.append(f"missing {key}")
        return default
    value = parse_number(data[key])
    if value is None or not math.isfinite(value):
        warnings.append(f"bad {key}={str(data[key])[:40]!r}")
        return default
    return value


def _number_list(text) -> Optional[List[float]]:
    if text is None:
        return []
    if not isinstance(text, str):
        return None
    text = text.strip()
    if not text:
        return []
    values = [parse_number(part) for part in text.split(LIST_SEPARATOR) if part.strip()]
    if any(v is None or not math.isfinite(v) for v in values):
        return None
    return values


_LAST_SAMPLES = (None, None)  # ((samples_x, samples_y) strings, their parsed array) of the last clean parse


def _parse_samples(data, warnings) -> np.ndarray:
    """(n, 2) float64 sample positions; the two strings change only when a sample is picked up, so the last
    clean parse is reused (as a copy) while they repeat."""
    global _LAST_SAMPLES
    key = (data.get("samples_x"), data.get("samples_y"))
    last_key, last = _LAST_SAMPLES
    if last is not None and type(key[0]) is str and type(key[1]) is str and key == last_key:
        return last.copy()
    n_warnings = len(warnings)
    out = _parse_samples_uncached(data, warnings)
    if len(warnings) == n_warnings and type(key[0]) is str and type(key[1]) is str:
        _LAST_SAMPLES = (key, out.copy())
    return out


def _parse_samples_uncached(data, warnings) -> np.ndarray:
    xs = _number_list(data.get("samples_x"))
    ys = _number_list(data.get("samples_y"))
    if xs is None or ys is None:
        warnings.append("bad samples_x/samples_y; ignored")
        return np.zeros((0, 2))
    if len(xs) != len(ys):
        warnings.append(f"samples_x has {len(xs)} values, samples_y {len(ys)}; truncated")
    n = min(len(xs), len(ys))
    if not n:
        return np.zeros((0, 2))
    out = np.empty((n, 2))  # the same float64 (n, 2) array as column_stack + astype, without their overhead
    out[:, 0], out[:, 1] = xs[:n], ys[:n]
    return out


def _parse_image(data, warnings):
    """(rgb 160x320x3, jpeg bytes) or (None, None) with a warning."""
    raw = _b64_to_bytes(data.get("image"))
    if raw is None:
        warnings.append("missing or undecodable image")
        return None, None
    rgb = _decode_jpeg_bytes(raw)
    if rgb is None:
        warnings.append("image bytes are not a JPEG/PNG")
        return None, None
    rows, cols = IMAGE_SHAPE[:2]
    h, w = rgb.shape[:2]
    if (h, w) != (rows, cols):
        if w * rows != h * cols:  # not the camera's 2:1 field of view
            warnings.append(f"image is {w}x{h}, expected {cols}x{rows}; rejected")
            return None, None
        warnings.append(f"image is {w}x{h}, resized to {cols}x{rows}")
        rgb = cv2.resize(rgb, (cols, rows), interpolation=cv2.INTER_AREA)
    return rgb, raw


def parse_telemetry(data) -> Telemetry:
    """Parse one telemetry dict; never raises.  Essential fields (image, position,
    yaw, pitch, roll, speed) must be valid for ``ok``; others fall back to safe
    defaults with a warning (unreadable ``picking_up`` counts as picking up, which
    blocks a blind pickup)."""
    tel = Telemetry()
    w = tel.warnings
    if not isinstance(data, dict):
        w.append(f"telemetry is a {type(data).__name__}, not an object")
        return tel
    try:
        essential_ok = True
        speed = _number_field(data, "speed", w)
        if speed is None or abs(speed) > MAX_ABS_SPEED:
            essential_ok = False
            if speed is not None:
                w.append(f"speed {speed} out of range")
        else:
            tel.speed = speed
        for key in ("yaw", "pitch", "roll"):
            value = _number_field(data, key, w)
            if value is None:
                essential_ok = False
            elif key == "yaw":
                tel.yaw = value % 360.0
            else:
                setattr(tel, key, signed_angle(value))
        pos = _number_list(data.get("position"))
        if pos is None or len(pos) != 2 or max(abs(pos[0]), abs(pos[1])) > MAX_ABS_COORD:
            w.append(f"bad position={str(data.get('position'))[:40]!r}")
            essential_ok = False
        else:
            tel.pos = (pos[0], pos[1])
        tel.image, tel.image_jpeg = _parse_image(data, w)
        essential_ok = essential_ok and tel.image is not None

        tel.steer = _number_field(data, "steering_angle", w, 0.0)
        tel.throttle = _number_field(data, "throttle", w, 0.0)
        tel.brake = _number_field(data, "brake", w, 0.0)
        tel.near_sample = _number_field(data, "near_sample", w, 0.0) != 0.0
        tel.picking_up = _number_field(data, "picking_up", w, 1.0) != 0.0
        count = _number_field(data, "sample_count", w)
        tel.sample_count = None if count is None else max(0, int(round(count)))
        tel.samples_xy = _parse_samples(data, w)
        if "sim_time" in data:
            tel.sim_time = _number_field(data, "sim_time", w)
        tel.ok = essential_ok
    except Exception as exc:  # belt and braces: parsing must never kill the server
        w.append(f"parser error {exc!r}")
        tel.ok = False
    return tel


def update_rover(rover, tel: Telemetry, now: float):
    """Copy a parsed frame into ``rover``.  A bad frame only clears
    ``telemetry_ok``; the first valid frame fixes start time, start position
    and the initial sample count."""
    rover.frame_count += 1
    rover.telemetry_ok = bool(tel.ok)
    if not tel.ok:
        return rover
    if rover.start_time is None:
        rover.start_time = now
    rover.total_time = max(0.0, now - rover.start_time)
    if rover.start_pos is None:
        rover.start_pos = tel.pos
    if rover.samples_initial is None and tel.sample_count is not None:
        rover.samples_initial = tel.sample_count
    rover.img = tel.image
    rover.pos = tel.pos
    rover.yaw, rover.pitch, rover.roll = tel.yaw, tel.pitch, tel.roll
    rover.vel = tel.speed
    rover.steer_telemetry = tel.steer
    rover.throttle_telemetry = tel.throttle
    rover.brake_telemetry = tel.brake
    rover.near_sample = tel.near_sample
    rover.picking_up = tel.picking_up
    rover.samples_remaining = tel.sample_count
    rover.samples_pos = (tel.samples_xy[:, 0].copy(), tel.samples_xy[:, 1].copy())
    return rover


# --- insets ----------------------------------------------------------------
class _InsetMemory:
    """Per-rover inset cache, kept in ``rover.inset_memory``."""

    def __init__(self):
        self.map_b64 = None  # last encoded inset 1
        self.frames_since_map = 0  # frames since inset 1 was rendered
        self.samples_all = np.zeros((0, 2))  # every sample position ever reported (located rule)
        self.truth_bgr = None  # ground truth backdrop, cached per truth array
        self.truth_id = None


def _memory(rover) -> _InsetMemory:
    mem = getattr(rover, "inset_memory", None)
    if mem is None:
        mem = _InsetMemory()
        rover.inset_memory = mem
    return mem


def _remember_samples(mem: _InsetMemory, rover):
    """The starter scores 'located' over the initial samples, so collected samples
    keep counting: remember every position seen, not only the remaining ones."""
    xs, ys = rover.samples_pos
    if len(xs) == 0:
        return
    new = np.column_stack([xs, ys])
    if mem.samples_all.size:
        d = np.abs(new[:, None, :] - mem.samples_all[None, :, :]).max(axis=2)
        new = new[d.min(axis=1) > 0.5]
    if len(new):
        mem.samples_all = np.vstack([mem.samples_all, new])


def _encode_b64_jpeg(bgr: np.ndarray) -> str:
    ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, INSET_JPEG_QUALITY])
    if not ok:
        raise ValueError("JPEG encoding failed")
    return base64.b64encode(buf.tobytes()).decode("ascii")


def _put_lines(img, lines, x=4, y0=11, color=(255, 255, 255)):
    for i, text in enumerate(lines):
        cv2.putText(img, text, (x, y0 + i * INSET_LINE_PX), cv2.FONT_HERSHEY_SIMPLEX,
                    INSET_FONT_SCALE, color, 1, cv2.LINE_AA)


def _pct(value: float) -> str:
    return "n/a" if value is None or not math.isfinite(value) else f"{value:.1f}%"


def inset_text_lines(rover, score) -> List[str]:
    """The starter's five lines: Time, Mapped, Fidelity, Located, Collected."""
    collected = "n/a"
    if rover.samples_initial is not None and rover.samples_remaining is not None:
        collected = str(rover.samples_initial - rover.samples_remaining)
    return [f"Time: {rover.total_time:.1f} s",
            f"Mapped: {_pct(score.mapped_pct)}",
            f"Fidelity: {_pct(score.fidelity_pct)}",
            f"Located: {score.located}",
            f"Collected: {collected}"]


def _truth_backdrop(mem: _InsetMemory, truth) -> np.ndarray:
    if truth is None:
        return np.zeros((WORLD_SIZE, WORLD_SIZE, 3), np.uint8)
    if mem.truth_id != id(truth) or mem.truth_bgr is None:
        grey = np.where(truth > 0, TRUTH_GREY, 0).astype(np.uint8)
        mem.truth_bgr = np.dstack([grey, grey, grey])
        mem.truth_id = id(truth)
    return mem.truth_bgr


def render_map_inset(rover) -> np.ndarray:
    """Inset 1 as BGR uint8 (200, 200, 3), north up: map over truth + score text."""
    mem = _memory(rover)
    _remember_samples(mem, rover)
    wm = rover.worldmap
    score = score_map(wm, rover.ground_truth, [tuple(p) for p in mem.samples_all])
    img = _truth_backdrop(mem, rover.ground_truth).copy()
    # worldmap is RGB [y, x]: R obstacle, G rock, B navigable -> BGR display
    img[wm[:, :, 0] > 0] = (0, 0, 200)
    img[wm[:, :, 2] > 0] = (255, 80, 0)
    img[wm[:, :, 1] > 0] = (0, 220, 255)
    for sx, sy in mem.samples_all:
        cv2.circle(img, (int(sx), int(sy)), SAMPLE_MARK_RADIUS_PX, (255, 255, 255), 1)
    x, y = rover.pos
    if math.isfinite(x) and math.isfinite(y):
        cv2.circle(img, (int(x), int(y)), ROVER_MARK_RADIUS_PX, (0, 255, 0), -1)
    img = np.ascontiguousarray(img[::-1])  # row 0 = y 0 in the array: flip for north up
    if INSET1_SCALE != 1:
        img = cv2.resize(img, None, fx=INSET1_SCALE, fy=INSET1_SCALE,
                         interpolation=cv2.INTER_NEAREST)
    _put_lines(img, inset_text_lines(rover, score))
    return img


def render_vision_inset(rover) -> np.ndarray:
    """Inset 2 as BGR uint8 (160, 320, 3): vision image + mode and target."""
    vision = getattr(rover, "vision_image", None)
    if not (isinstance(vision, np.ndarray) and vision.shape == IMAGE_SHAPE
            and vision.dtype == np.uint8):
        vision = np.zeros(IMAGE_SHAPE, np.uint8)
    img = cv2.cvtColor(vision, cv2.COLOR_RGB2BGR)
    target = rover.target
    try:
        target_text = "none" if target is None else f"({float(target[0]):.1f}, {float(target[1]):.1f})"
    except (TypeError, ValueError, IndexError):
        target_text = str(target)[:30]
    _put_lines(img, [f"mode: {str(rover.mode)[:30]}", f"target: {target_text}"],
               color=(255, 255, 255))
    return img


def create_output_images(rover) -> Tuple[str, str]:
    """(inset 1, inset 2) as base64 JPEG strings, no ``data:`` prefix.

    Inset 1 is rendered on the first call and then every
    ``INSET1_EVERY_N_FRAMES`` calls; in between the cached string is resent.
    """
    mem = _memory(rover)
    if mem.map_b64 is None or mem.frames_since_map + 1 >= INSET1_EVERY_N_FRAMES:
        mem.map_b64 = _encode_b64_jpeg(render_map_inset(rover))
        mem.frames_since_map = 0
    else:
        mem.frames_since_map += 1
    return mem.map_b64, _encode_b64_jpeg(render_vision_inset(rover))
