"""The control laws by name. Each law declares its name, gains (defaults from thesis
Table 5.1, admissible ranges), stiffness and internal state beside its code with
``@control_law`` (``nonholo.control.declare``); importing its module registers it.

**Adding a law** is one new module in this package plus one line in ``LAW_MODULES``
below (docs/controllers-api.md). A ``ControlLaw`` describes a family of laws (tracking
or posture); a ``ControllerConfig`` is one choice of law and gains, ready for the
simulator.
"""
from __future__ import annotations

import importlib
from collections.abc import Mapping

from nonholo.control.declare import (  # noqa: F401 - the registry's public names
    ABOVE_MINUS_ONE, ANY, CONTROLLERS, GOAL_FIELDS, LAWS, MAX_LAW_FIELDS, NONZERO, POSITIVE, POSTURE_CONTROLLERS,
    UNIT_INTERVAL, ControlLaw, ControllerConfig, ControllerDeclarationError, Gain, GainRule, TrackingController,
    check_gains, control_law, initial_state, unregister)
from nonholo.errors import NonholoInputError

# The built-in laws: importing a module registers the laws it declares, in this order.
LAW_MODULES = (
    "nonholo.control.linearization",          # approximate-linearization, nonlinear
    "nonholo.control.cascaded",               # cascaded (linear, sine)
    "nonholo.control.kanayama",               # kanayama
    "nonholo.control.feedback_linearization",  # offset-point, dynamic-feedback
    "nonholo.control.posture",                # time-varying, polar, dynamic-feedback-posture
)
for _module in LAW_MODULES:
    importlib.import_module(_module)

# Gains of the follower laws (separation-bearing, separation-separation), validated by
# the same check as the root laws' gains.
FOLLOWER_GAINS = {"k1": Gain(1.0, POSITIVE), "k2": Gain(1.0, POSITIVE)}


def follower_gains(values: Mapping[str, float], law: str = "follower") -> dict[str, float]:
    """Follower gains resolved against ``FOLLOWER_GAINS`` (defaults fill the rest) and
    validated; raises NonholoInputError with the registry's one-line messages."""
    return check_gains(law, dict(values), tuple(FOLLOWER_GAINS), {g: d.default for g, d in FOLLOWER_GAINS.items()},
                       {g: d.rule for g, d in FOLLOWER_GAINS.items()})


def controller(name: str, variant: str | None = None, **gains: float) -> ControllerConfig:
    """A configured root law, tracking or posture: ``controller("kanayama", kx=5)``.

    Unknown names list the valid ones; unknown gains list the controller's gains.
    """
    spec = LAWS.get(name)
    if spec is None:
        raise NonholoInputError(f"unknown controller {name!r} (valid: {', '.join(LAWS)})")
    return spec.configure(gains, variant)
