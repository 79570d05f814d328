"""The starter project's scoring rules, in one place.

Mapped = correct navigable cells / ground-truth navigable cells;
Fidelity = correct navigable cells / all cells marked navigable (blue > 0);
Located = samples with a rock (green) cell within 3 px of their truncated position.
"""
from dataclasses import asdict, dataclass

import numpy as np

LOCATE_RADIUS_PX = 3  # a rock cell closer than this to a sample locates it, px


@dataclass
class MapScore:
    mapped_pct: float  # nan without ground truth
    fidelity_pct: float  # nan without ground truth or with nothing mapped
    good_cells: int
    marked_cells: int
    truth_cells: int
    located: int

    def as_dict(self):
        return asdict(self)


def load_ground_truth(path):
    """Read map_bw.png as a 200x200 uint8 array (255 navigable), [y, x]."""
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise ValueError(f"cannot read ground-truth map {path}")
    return np.where(img > 127, 255, 0).astype(np.uint8)


def count_located(worldmap, samples_xy):
    """Samples with a green worldmap cell within LOCATE_RADIUS_PX (starter rule)."""
    rock_y, rock_x = np.nonzero(worldmap[:, :, 1])
    if rock_x.size == 0:
        return 0
    located = 0
    for sx, sy in samples_xy:
        d2 = (int(sx) - rock_x) ** 2 + (int(sy) - rock_y) ** 2
        if d2.min() < LOCATE_RADIUS_PX ** 2:
            located += 1
    return located


def score_map(worldmap, ground_truth=None, samples_xy=()):
    """Score a [y, x] RGB worldmap; metrics are nan when ground truth is None."""
    marked = worldmap[:, :, 2] > 0
    located = count_located(worldmap, samples_xy)
    if ground_truth is None:
        return MapScore(float("nan"), float("nan"), 0, int(marked.sum()), 0, located)
    truth = ground_truth > 0
    good = int(np.count_nonzero(marked & truth))
    n_marked = int(np.count_nonzero(marked))
    n_truth = int(np.count_nonzero(truth))
    mapped = 100.0 * good / n_truth if n_truth else float("nan")
    fidelity = 100.0 * good / n_marked if n_marked else float("nan")
    return MapScore(mapped, fidelity, good, n_marked, n_truth, located)
