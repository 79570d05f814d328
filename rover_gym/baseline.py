"""The project's own autonomy client as a Gymnasium policy (the baseline to beat).

`AutonomyPolicy(obs) -> action` rebuilds the simulator's string telemetry from
the observation (numbers with the simulator's formatting, the frame as a
lossless PNG of the pixels the env observed) and runs `autonomy.AutonomyClient`
on it, so the baseline drives exactly as it does on the wire and in
`sim.mission` (tests/test_gym.py checks the trajectories match frame for frame), except that
the action space has no `fixed_turn`: the baseline turns in place by steering, as the client
does on a link whose fixed turns are off.
"""
from __future__ import annotations

import base64

import numpy as np

from rover_gym.env import PICKUP_THRESHOLD, TELEMETRY_FIELDS

PNG_COMPRESSION = 1  # cv2 PNG level: fast; lossless at every level


def telemetry_from_obs(obs, sim_time_field: bool = True) -> dict:
    """The simulator-format telemetry dict for an env observation (sample positions left empty).

    sim_time_field: add the twin-only `sim_time` clock (the lockstep loop sends it; the real one does not)."""
    import cv2

    from sim.twin import format_angle_0_360, format_n

    t = dict(zip(TELEMETRY_FIELDS, np.asarray(obs["telemetry"], np.float64).tolist()))
    ok, png = cv2.imencode(".png", np.ascontiguousarray(obs["image"][:, :, ::-1]),
                           [cv2.IMWRITE_PNG_COMPRESSION, PNG_COMPRESSION])
    if not ok:
        raise ValueError("cannot encode the observed image as PNG")
    tel = {
        "steering_angle": format_n(t["steer"]), "throttle": format_n(t["throttle"]),
        "brake": format_n(t["brake"]), "speed": format_n(t["speed"]),
        "position": f"{format_n(t['x'])};{format_n(t['y'])}",
        "pitch": format_angle_0_360(t["pitch"]), "yaw": format_angle_0_360(t["yaw"]),
        "roll": format_angle_0_360(t["roll"]),
        "near_sample": str(int(round(t["near_sample"]))), "picking_up": str(int(round(t["picking_up"]))),
        "sample_count": str(int(round(t["samples_remaining"]))), "samples_x": "", "samples_y": "",
        "image": base64.b64encode(png.tobytes()).decode("ascii"),
    }
    if sim_time_field:
        tel["sim_time"] = f"{t['sim_time']:.4f}"
    return tel


def action_from_reply(event: str, payload: dict) -> np.ndarray:
    """An env action for one client reply (`data`, `pickup` or `manual`)."""
    if event == "pickup":
        return np.array([0.0, 0.0, 0.0, 1.0], np.float32)
    if event == "data":
        return np.array([float(payload["throttle"]), float(payload.get("brake", 0.0)),
                         float(payload["steering_angle"]), 0.0], np.float32)
    return np.array([0.0, 1.0, 0.0, 0.0], np.float32)  # manual / anything else: hold still


class AutonomyPolicy:
    """`autonomy.AutonomyClient` behind `policy(obs) -> action`; `reset()` before a new episode.

    clock: the client's wall clock (a callable, seconds); None = the observation's capture time,
    sent as the lockstep loop's `sim_time` field.  `AutonomyPolicy.for_env(env)` takes both from
    the env's timing: under unity timing no clock is sent and the client reads the env's
    `client_clock` (capture time + half the round trip), exactly as in `sim.mission`.
    """

    def __init__(self, ground_truth=None, home_by_s=None, clock=None):
        self.ground_truth = ground_truth
        self.home_by_s = home_by_s
        self.clock = clock
        self.reset()

    @classmethod
    def for_env(cls, env, home_by_s=None):
        e = env.unwrapped
        return cls(ground_truth=e.world.nav_truth, home_by_s=home_by_s,
                   clock=None if e.timing.sends_sim_time else e.client_clock)

    def reset(self) -> None:
        import time

        from autonomy import AutonomyClient

        # the action space has no fixed_turn: the baseline steers its turns in place (fixed_turns=False)
        self.client = AutonomyClient(ground_truth=self.ground_truth, insets=False, home_by_s=self.home_by_s,
                                     clock=self.clock or time.monotonic, fixed_turns=False)

    def __call__(self, obs) -> np.ndarray:
        tel = telemetry_from_obs(obs, sim_time_field=self.clock is None)
        event, payload = self.client.handle_telemetry(tel)
        action = action_from_reply(event, payload)
        assert event != "pickup" or action[3] >= PICKUP_THRESHOLD
        return action

    @property
    def mission_complete(self) -> bool:
        """The client thinks it is done (home with every sample)."""
        return bool(getattr(self.client.rover, "mission_complete", False))

    @property
    def worldmap(self) -> np.ndarray:
        """The client's own map (200x200x3 uint8, [y, x]), scored by `evaluation.metrics.score_map`."""
        return self.client.rover.worldmap
