"""The one mutable object that carries a rover's state between frames.

Telemetry fills the first block, perception the second, decision the third.
Modules that need private memory keep it in their own attribute (for example
``rover.perception_memory`` or ``rover.nav``) so they never fight over names.
"""
import numpy as np

WORLD_SIZE = 200  # world and map edge, metres == pixels (1 px = 1 m)
IMAGE_SHAPE = (160, 320, 3)  # camera frame rows, columns, RGB


class RoverState:
    def __init__(self, ground_truth=None, clock_start=None):
        # --- telemetry (set by supporting_functions.update_rover) ---------
        self.start_time = clock_start  # clock value at first telemetry, s
        self.total_time = 0.0  # seconds since first telemetry
        self.frame_count = 0  # telemetry frames handled
        self.img = None  # current camera frame, RGB uint8 160x320x3
        self.pos = (np.nan, np.nan)  # (x, y) world metres
        self.yaw = 0.0  # degrees CCW from +x, [0, 360)
        self.pitch = 0.0  # degrees, signed (-180, 180], positive = nose down
        self.roll = 0.0  # degrees, signed (-180, 180]
        self.vel = 0.0  # m/s, negative when reversing
        self.steer_telemetry = 0.0  # steering echoed by the simulator, degrees
        self.throttle_telemetry = 0.0  # throttle echoed by the simulator
        self.brake_telemetry = 0.0  # brake echoed by the simulator
        self.near_sample = False  # simulator says a sample is in pickup reach
        self.picking_up = False  # simulator is running the pickup arm
        self.samples_remaining = None  # simulator's sample_count (remaining)
        self.samples_initial = None  # sample_count at the first telemetry
        self.samples_pos = (np.zeros(0), np.zeros(0))  # remaining samples (xs, ys), scoring only
        self.start_pos = None  # (x, y) of the first valid telemetry: "home"
        self.telemetry_ok = False  # last frame parsed cleanly

        # --- perception (set by perception.perception_step) ---------------
        self.nav_angles = np.zeros(0)  # navigable pixels, rover-centric radians (left +)
        self.nav_dists = np.zeros(0)  # navigable pixels, metres from rover origin
        self.obs_angles = np.zeros(0)
        self.obs_dists = np.zeros(0)
        self.rock_angles = np.zeros(0)
        self.rock_dists = np.zeros(0)
        self._vision_image = np.zeros(IMAGE_SHAPE, dtype=np.uint8)
        self._vision_draw = None  # perception's pending drawing of it (see vision_image)
        self.worldmap = np.zeros((WORLD_SIZE, WORLD_SIZE, 3), dtype=np.uint8)  # [y, x]: R obstacle, G rock, B navigable
        self.rocks_world = []  # remembered sample-rock world positions [(x, y), ...]
        self.map_updated = False  # this frame passed the tilt gate and updated the map

        # --- decision (set by decision.decision_step) ---------------------
        self.mode = "forward"  # current mode name, shown in the vision inset
        self.target = None  # (x, y) the decision is heading for, or None
        self.throttle = 0.0  # command, [-1, 1]
        self.brake = 0.0  # command, >= 0
        self.steer = 0.0  # command, degrees, clamped to +-15, positive = left
        self.send_pickup = False  # ask the simulator to pick up this frame
        self.fixed_turns = False  # the link can send the simulator's fixed_turn (AutonomyClient sets it)
        self.fixed_turn = None  # send fixed_turn this frame instead of data: (degrees CCW +, deg/s) (navigation.fixed_turn)
        self.pickup_sent_at = None  # total_time of the last pickup request
        self.mission_complete = False  # all collected and home
        self.home_by_s = None  # head home so as to arrive by this mission time, s (None: decision.HOME_BY_S)

        # --- scoring / display ---------------------------------------------
        self.ground_truth = ground_truth  # 200x200 uint8 map_bw (255 navigable) or None

    # --- the vision image, drawn only when someone looks -------------------
    @property
    def vision_image(self):
        """Camera view with the thresholds colour-coded, RGB uint8 160x320x3 (shown as inset 2).

        Perception hands over a drawing function instead of the image (defer_vision_image): missions
        on the twin run without insets, and drawing it every frame was ~5 % of the client's time."""
        if self._vision_draw is not None:
            self._vision_image = self._vision_draw()
            self._vision_draw = None
        return self._vision_image

    @vision_image.setter
    def vision_image(self, image):
        self._vision_image = image
        self._vision_draw = None

    def defer_vision_image(self, draw):
        """Set vision_image to ``draw()``, called when (and if) vision_image is next read."""
        self._vision_draw = draw
