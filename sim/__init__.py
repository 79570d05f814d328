"""Headless digital twin of the RoboND rover simulator.

`world` holds the static scene (terrain, rocks, sample spots), `render` draws the
rover camera frame; physics, twin, wire and mission build on those two.
"""
