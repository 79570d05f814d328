"""Tiny synthetic worlds for twin tests that need no shared data (shared by several test files)."""
import numpy as np

from sim.world import World


def flat_world():
    """Flat, all-navigable 200 m world, start at (100, 100), eight samples in a row at y = 60."""
    return World(terrain_height=np.zeros((513, 513), np.float32),
                 sand_weight=np.ones((512, 512), np.float32),
                 rock_top=np.zeros((2001, 2001), np.float32),
                 rock_bottom=np.zeros((2001, 2001), np.float32),
                 nav_truth=np.full((200, 200), 255, np.uint8),
                 sample_spots=np.array([[100.0 + i, 60.0] for i in range(8)]),
                 start_xy=(100.0, 100.0), start_yaw_training=0.0, name="flat-test")
