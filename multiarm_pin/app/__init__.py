"""The shell around the library: scenario files, runs and their results, plots, replay, CLI."""

REPLAY_FPS = 30
"""Frames per second of the replay page (and the default of ``multiarm-pin replay --fps``)."""
