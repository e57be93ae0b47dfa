"""The scripted expert: the paper's planner and inverse-dynamics controller in the loop.

:class:`ExpertPolicy` replans every gait cycle from the measured state (receding horizon:
footholds, COG path, swing paths) heading +x (or, in an env with a ``command``, advancing by the
commanded (vx, vy) times the cycle's duration and turning by the commanded yaw rate times it: forwards,
backwards, sideways, turning, in place), with the body pitched along the slope of the footholds
(``ExpertConfig.body_pitch``; the paper keeps it level), and runs the computed-torque
controller (:class:`agents.control.controller.ComputedTorqueController`) at physics rate through the env's
control hook. :func:`attach_expert` builds it and installs it as that hook; an expert that is not its env's
hook refuses to act (a ``RuntimeError`` naming ``attach_expert``), since its actions alone are zero.

*Its own model* (``ExpertConfig.model="nominal"``, the default). The expert plans and controls with
a nominal model of the robot (:class:`agents.control.nominal.NominalModel`, compiled from the
robot configuration the env was built from, before any randomization) and nominal assumptions
(``ExpertConfig``: the configuration's masses and centres of mass, and a friction coefficient
``friction`` for its cones, with margin below the nominal 1.0). What it reads from the simulator
is what a robot measures, and nothing else:

- joint angles and velocities (encoders): ``qpos[7:]``, ``qvel[6:]``;
- base pose and twist (state estimator): ``qpos[:7]`` (position, world; quaternion w, x, y, z)
  and ``qvel[:6]`` (linear velocity, world; angular velocity, base frame);
- foot contacts (contact switches), one boolean per foot: whether the foot geom touches the
  terrain in MuJoCo's contact list of the current step, and the feet's contact sensors' found
  flags (the same booleans after the previous step's constraint solve) for late touch-downs;
- the height field as its map (``env.unwrapped.terrain``), and the clock ``data.time``.

Every copy goes into the nominal model's data (:meth:`NominalModel.measure`), whose position and
velocity stages give the mass matrix, bias forces, foot Jacobians and COG the controller and the
planner use. The simulator's masses, inertias, friction, motor strength, contact forces and COG
are never read. When the simulated robot is exactly nominal (checked at every reset by
:meth:`NominalModel.matches`) and ``share_nominal_world`` is on, the controller reads the same
terms straight from the simulator's data: they equal the nominal model's bit for bit (tested), and
the copy would only cost time. ``model="oracle"`` reads the simulator's live model and data, and its
cones use the simulated friction (for comparison; never the default).

It follows SB3's ``predict`` protocol so the evaluation code runs it like a learned agent;
``predict`` returns the zero action because the work is done in the physics-rate hook (the
residual RL agent adds its action on top of it).

Its parts, one job per module:

- :mod:`~agents.expert.config`: :class:`ExpertConfig`, the settings;
- :mod:`~agents.expert.cycle`: cycle planning from the measured footholds, and the fallbacks when a plan fails
  (:data:`STRIDE_FALLBACKS`, then standing still for one cycle; every failure is recorded in
  :attr:`ExpertPolicy.failure_log`);
- :mod:`~agents.expert.command`: from the env's command to a cycle's phases, turn and stride;
- :mod:`~agents.expert.friction`: the friction the cones and footholds assume (footholds steeper than its
  pyramid holds are refused, :func:`foothold_limits_for_friction`), steep ground, and slips;
- :mod:`~agents.expert.recovery`: replanning when the base is pushed off its plan;
- :mod:`~agents.expert.hook`: the physics-rate control, one method per physics step (the measurement, the checks,
  the controller's compiled step or in its place its readable call, the adaptive gains);
- :mod:`~agents.expert.policy`: :class:`ExpertPolicy`, composing them into the env's physics-rate controller, and
  :func:`attach_expert`.

It never raises out of a rollout: any failure of the planner is handled like a failed plan, and a failure of
the controller at a physics step (logged with its reason) keeps the last good torques for that step.
"""

from agents.expert.config import EXPERT_MODELS, ExpertConfig
from agents.expert.cycle import STRIDE_FALLBACKS
from agents.expert.friction import foothold_limits_for_friction
from agents.expert.policy import ExpertPolicy, attach_expert

__all__ = [
    "EXPERT_MODELS",
    "STRIDE_FALLBACKS",
    "ExpertConfig",
    "ExpertPolicy",
    "attach_expert",
    "foothold_limits_for_friction",
]
