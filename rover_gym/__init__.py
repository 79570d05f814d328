"""Gymnasium environment for the RoboND rover twin: `gymnasium.make("RoverTwin-v0", ...)`.

Importing this package registers the id (or use `gymnasium.make("rover_gym:RoverTwin-v0")`).
See `rover_gym.env.RoverTwinEnv` for spaces, reward and arguments, docs/gym.md for the why.
"""
import gymnasium

ENV_ID = "RoverTwin-v0"  # the registered environment id

if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point="rover_gym.env:RoverTwinEnv")
