"""The shipped YAML presets (robot, terrain, suites, randomization, RL, sweeps): installed as the package data
``quad_uneven_env.configs``; see :func:`quad_uneven_env.config.shipped_config_dir`."""
