"""Policies and entry points: inverse-dynamics control, the scripted expert, residual RL, CLI."""
