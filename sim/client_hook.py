"""Opt-in bootstrap that runs a third-party starter-style client *unchanged* on the twin.

    ROVER_HOOK_PORT=4601 ROVER_HOOK_MAP=/tmp/worldmap.npy [ROVER_HOOK_GROUND_TRUTH=truth.png] \\
        python sim/client_hook.py PATH/TO/drive_rover.py [their arguments]

It patches the process from outside, then runs their `drive_rover.py` as
`__main__` (as `python drive_rover.py` would, from its own folder):

* **numpy shims**: aliases numpy 1.24/2.0 removed (`np.float`, `np.int`,
  `np.bool`, `np.NaN`, ...) are put back, only where missing, so Python
  3.5-era clients import and run on a current numpy.
* **matplotlib shim**: `matplotlib.image.imread` of a missing file named like
  the ground-truth map (`map_bw.png`; the starter reads
  `../calibration_images/map_bw.png` relative to where it is started) returns
  the map in `ROVER_HOOK_GROUND_TRUTH` (the twin world's truth).  Without
  matplotlib installed, a minimal `matplotlib.image` with `imread` stands in.
* **OpenCV shim**: `cv2.putText` onto a float image (OpenCV 5 draws on 8-bit
  images only; the starter writes its statistics onto a float32 map) draws
  through an 8-bit mask instead of raising.
* **port**: `eventlet.listen((host, port))` binds `127.0.0.1:ROVER_HOOK_PORT`
  instead (the starter hard-codes port 4567 on every interface).
* **worldmap snapshots**: a background thread finds the client's rover state
  (a global of its `__main__` with a `worldmap` array, e.g. the starter's
  `Rover`) and writes `worldmap` to `ROVER_HOOK_MAP` (.npy, atomically) every
  `ROVER_HOOK_SNAPSHOT_S` seconds and once more on SIGTERM/exit, so the
  evaluator can score the client's own map.

This file runs inside the foreign process: it imports nothing from the project,
and its own folder is taken off `sys.path` so the client's modules
(`perception`, `decision`, ...) are the ones found.
"""
from __future__ import annotations

import atexit
import os
import runpy
import signal
import sys
import threading
import time

ENV_PORT = "ROVER_HOOK_PORT"  # port the client's server must bind
ENV_MAP = "ROVER_HOOK_MAP"  # .npy path for worldmap snapshots
ENV_GROUND_TRUTH = "ROVER_HOOK_GROUND_TRUTH"  # PNG served in place of a missing map_bw.png
ENV_SNAPSHOT_S = "ROVER_HOOK_SNAPSHOT_S"  # seconds between snapshots
DEFAULT_SNAPSHOT_S = 1.0  # s between worldmap snapshots
GROUND_TRUTH_NAMES = ("map_bw.png",)  # file names the matplotlib shim may stand in for
STATE_NAMES = ("Rover", "rover", "ROVER")  # globals looked at first for the rover state
NUMPY_ALIASES = {  # removed numpy name -> replacement (applied only when numpy lacks the name)
    "float": float, "int": int, "bool": bool, "object": object, "str": str, "complex": complex,
    "long": int, "unicode": str,
}
NUMPY_RENAMED = {  # removed numpy name -> surviving numpy attribute
    "float_": "float64", "complex_": "complex128", "NaN": "nan", "NAN": "nan", "Inf": "inf", "Infinity": "inf",
    "PINF": "inf", "infty": "inf", "product": "prod", "cumproduct": "cumprod", "sometrue": "any",
    "alltrue": "all", "round_": "round", "row_stack": "vstack",
}


# ----------------------------------------------------------------------------- shims
def install_numpy_shims() -> list:
    """Put back removed numpy aliases; returns the names added."""
    import numpy as np

    added = []
    for name, value in NUMPY_ALIASES.items():
        if name not in np.__dict__:
            setattr(np, name, value)
            added.append(name)
    for name, target in NUMPY_RENAMED.items():
        if name not in np.__dict__ and hasattr(np, target):
            setattr(np, name, getattr(np, target))
            added.append(name)
    if "NINF" not in np.__dict__:
        np.NINF = -np.inf
        added.append("NINF")
    if "asfarray" not in np.__dict__:
        np.asfarray = lambda a, dtype=np.float64: np.asarray(a, dtype=dtype if dtype is not None else np.float64)
        added.append("asfarray")
    return added


def _read_png_as_matplotlib(path):
    """What matplotlib.image.imread returns for a PNG: float32 in 0..1, 2-D for greyscale."""
    import numpy as np
    from PIL import Image

    with Image.open(path) as img:
        arr = np.asarray(img)
    return arr.astype(np.float32) / (65535.0 if arr.dtype == np.uint16 else 255.0)


def install_matplotlib_shim(ground_truth_path) -> str:
    """Serve the twin's truth for a missing map_bw.png; returns what was done."""
    def wants_truth(fname):
        name = os.path.basename(str(fname))
        return ground_truth_path and name in GROUND_TRUTH_NAMES and not os.path.exists(str(fname))

    try:
        import matplotlib

        matplotlib.use("Agg")  # headless: a client that plots must not need a display
        import matplotlib.image as mpimg
    except ImportError:
        import types

        mpl = types.ModuleType("matplotlib")
        mpimg = types.ModuleType("matplotlib.image")
        mpimg.imread = lambda fname, format=None: _read_png_as_matplotlib(
            ground_truth_path if wants_truth(fname) else fname)
        mpl.image = mpimg
        mpl.use = lambda *a, **k: None
        sys.modules["matplotlib"], sys.modules["matplotlib.image"] = mpl, mpimg
        return "stand-in matplotlib.image"
    original = mpimg.imread

    def imread(fname, *args, **kwargs):
        if wants_truth(fname):
            return original(ground_truth_path, *args, **kwargs)
        return original(fname, *args, **kwargs)

    mpimg.imread = imread
    return "matplotlib.image.imread wrapped"


def install_opencv_shim() -> bool:
    """cv2.putText on a float image: OpenCV 5 draws text on 8-bit images only, OpenCV 3 drew on any depth
    (the starter writes its map statistics onto a float32 map)."""
    try:
        import cv2
        import numpy as np
    except ImportError:
        return False
    original = cv2.putText

    def putText(img, text, org, fontFace, fontScale, color, thickness=1, lineType=8, bottomLeftOrigin=False):
        if isinstance(img, np.ndarray) and img.dtype != np.uint8 and img.ndim in (2, 3):
            mask = np.zeros(img.shape[:2], np.uint8)
            original(mask, text, org, fontFace, fontScale, 255, thickness, lineType, bottomLeftOrigin)
            colour = np.asarray(color, np.float64).reshape(-1)
            img[mask > 0] = colour[: img.shape[2]] if img.ndim == 3 else colour[0]
            return img
        return original(img, text, org, fontFace, fontScale, color, thickness, lineType, bottomLeftOrigin)

    cv2.putText = putText
    return True


def redirect_eventlet_listen(port: int) -> bool:
    """Make eventlet.listen bind 127.0.0.1:port whatever address the client asks for."""
    try:
        import eventlet
    except ImportError:
        return False
    original = eventlet.listen

    def listen(addr, *args, **kwargs):
        if isinstance(addr, tuple) and len(addr) >= 2:
            addr = ("127.0.0.1", int(port), *addr[2:])
        return original(addr, *args, **kwargs)

    eventlet.listen = listen
    return True


# ----------------------------------------------------------------------------- worldmap snapshots
def find_worldmap(namespace: dict):
    """The client's worldmap: `worldmap` of a global rover-state object (preferred names first), or None."""
    import numpy as np

    names = [n for n in STATE_NAMES if n in namespace] + [n for n in list(namespace) if n not in STATE_NAMES]
    for name in names:
        obj = namespace.get(name)
        if obj is None or isinstance(obj, type) or type(obj).__name__ == "module":
            continue
        m = getattr(obj, "worldmap", None)
        if isinstance(m, np.ndarray) and m.ndim == 3 and m.shape[2] >= 3:
            return m
    return None


def write_snapshot(worldmap, path) -> None:
    """np.save via a temp file + os.replace: the reader never sees half a file."""
    import numpy as np

    tmp = f"{path}.tmp.npy"
    np.save(tmp, np.array(worldmap, copy=True))
    os.replace(tmp, path)


class Snapshotter:
    """Writes the client's worldmap every `every_s` seconds from a daemon thread, and on demand."""

    def __init__(self, path, every_s=DEFAULT_SNAPSHOT_S):
        self.path, self.every_s = path, float(every_s)
        self._sleep = time.sleep  # kept before a client's eventlet.monkey_patch() can green it
        self._lock = threading.Lock()

    def snapshot(self) -> bool:
        main = sys.modules.get("__main__")
        m = find_worldmap(vars(main)) if main is not None else None
        if m is None:
            return False
        with self._lock:
            try:
                write_snapshot(m, self.path)
            except (OSError, ValueError):
                return False
        return True

    def _loop(self):
        while True:
            self._sleep(self.every_s)
            self.snapshot()

    def start(self):
        threading.Thread(target=self._loop, name="worldmap-snapshots", daemon=True).start()
        atexit.register(self.snapshot)

        def on_term(signum, frame):
            self.snapshot()
            os._exit(0)

        signal.signal(signal.SIGTERM, on_term)


# ----------------------------------------------------------------------------- main
def run_client(client_path: str, args=()) -> None:
    """Run their drive_rover.py as __main__ from its own folder, as `python drive_rover.py` would."""
    client_path = os.path.abspath(client_path)
    folder = os.path.dirname(client_path)
    here = os.path.dirname(os.path.abspath(__file__))
    sys.path[:] = [p for p in sys.path if os.path.abspath(p or ".") != here]
    sys.path.insert(0, folder)
    os.chdir(folder)
    sys.argv = [client_path, *args]
    runpy.run_path(client_path, run_name="__main__")


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or not os.path.isfile(argv[0]):
        sys.stderr.write("usage: python sim/client_hook.py PATH/TO/drive_rover.py [args]\n")
        return 2
    install_numpy_shims()
    install_matplotlib_shim(os.environ.get(ENV_GROUND_TRUTH))
    install_opencv_shim()
    port = os.environ.get(ENV_PORT)
    if port:
        redirect_eventlet_listen(int(port))
    if os.environ.get(ENV_MAP):
        Snapshotter(os.environ[ENV_MAP], float(os.environ.get(ENV_SNAPSHOT_S, DEFAULT_SNAPSHOT_S))).start()
    run_client(argv[0], argv[1:])
    return 0


if __name__ == "__main__":
    sys.exit(main())
