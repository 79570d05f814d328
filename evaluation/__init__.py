"""Scoring shared by the live insets, the replay tool and the twin's missions."""
