"""Where the read-only reference data lives (never copied into the project).

Everything that needs ../shared asks here, so one environment variable
(ROVER_SHARED) moves it and tests can skip cleanly when it is absent.
"""
import os
from pathlib import Path

PROJECT_DIR = Path(__file__).resolve().parent
SHARED_ENV_VAR = "ROVER_SHARED"  # environment variable naming the shared folder
DEFAULT_SHARED_DIR = PROJECT_DIR.parent / "shared"  # ../shared beside the checkout


def shared_dir() -> Path:
    """The shared data folder (may not exist)."""
    return Path(os.environ.get(SHARED_ENV_VAR, DEFAULT_SHARED_DIR)).expanduser()


def udacity_dir() -> Path:
    return shared_dir() / "udacity-rover"


def test_dataset_dir() -> Path:
    return udacity_dir() / "test_dataset"


def ground_truth_map_path() -> Path:
    return udacity_dir() / "calibration_images" / "map_bw.png"


def world_dir() -> Path:
    return udacity_dir() / "world"


def real_logs_dir() -> Path:
    return shared_dir() / "real-logs"


def available(path: Path) -> bool:
    """True when a shared file or folder is present (tests skip otherwise)."""
    return Path(path).exists()
