"""Record the twin's frames as a simulator-format log (robot_log.csv + IMG/).

Uses `replay.log_format.LogWriter`, so `python -m replay` reads twin recordings
exactly like real ones.  File-name timestamps are a fixed wall-clock origin plus
the simulated time, so a recording made faster than real time still carries the
simulator's frame spacing.
"""
from __future__ import annotations

import time


class TwinRecorder:
    """Writes one log row + JPEG per twin frame (the frame must have been rendered)."""

    def __init__(self, folder, origin_s: float | None = None):
        from replay.log_format import LogWriter

        self.writer = LogWriter(folder)
        self.folder = self.writer.folder
        self.origin_s = time.time() if origin_s is None else float(origin_s)
        self.frames = 0

    def write(self, jpeg_bytes, steer, throttle, brake, speed, x, y, pitch, yaw, roll, sim_time):
        self.writer.write(jpeg_bytes, steer, throttle, brake, speed, x, y, pitch, yaw, roll,
                          when=self.origin_s + float(sim_time))
        self.frames += 1

    def write_twin(self, twin) -> bool:
        """Record the twin's current frame; False when it has no rendered JPEG."""
        if twin.last_jpeg is None:
            return False
        s = twin.physics.state
        c = twin.controls
        speed = 0.0 if (twin.arm.active or abs(s.v) < 0.01) else s.v
        self.write(twin.last_jpeg, max(-15.0, min(15.0, c.steer)), c.throttle, c.brake, speed,
                   s.x, s.y, s.pitch, s.yaw, s.roll, twin.sim_time)
        return True

    def close(self):
        self.writer.close()
