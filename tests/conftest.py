"""Shared fixtures: locate ../shared data and skip with a reason when it is absent."""
import pytest

import shared_data


def _require(path, what):
    if not shared_data.available(path):
        pytest.skip(f"{what} not found at {path} (set {shared_data.SHARED_ENV_VAR} to the shared folder)")
    return path


@pytest.fixture(scope="session")
def test_dataset_dir():
    return _require(shared_data.test_dataset_dir(), "Udacity test_dataset")


@pytest.fixture(scope="session")
def ground_truth_path():
    return _require(shared_data.ground_truth_map_path(), "ground-truth map_bw.png")


@pytest.fixture(scope="session")
def ground_truth(ground_truth_path):
    from evaluation.metrics import load_ground_truth

    return load_ground_truth(ground_truth_path)


@pytest.fixture(scope="session")
def world_dir():
    return _require(shared_data.world_dir(), "simulator world export")


@pytest.fixture(scope="session")
def real_logs_dir():
    return _require(shared_data.real_logs_dir(), "real recorded logs")


@pytest.fixture
def map_only_search(monkeypatch):
    """The sample search as on any world but the real canyon: no sample spots (navigation.sample_spots), so tests
    of the map-only search rules can stand a rover near the canyon's start."""
    from navigation import sample_spots

    monkeypatch.setattr(sample_spots, "USE_CANYON_SPOTS", False)
