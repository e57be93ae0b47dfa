"""Planners: gait, footholds, COG path, swing legs, joint references (pure functions, no simulator)."""
