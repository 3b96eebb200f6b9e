"""The thesis's published numbers, kept as data (never computed, never read at run time).

Source: S. Ahmed, *Feedback Linearization Techniques for Collaborative Nonholonomic
Robots*, MSc thesis, Universiti Teknologi PETRONAS, Chapter 5:

* Tables 5.2–5.5 (§5.3.1–5.3.4): mean, standard deviation and variance of the position
  error norm (m; the thesis labels the variance "m", it is m²) per test and controller,
  copied digit for digit, including the two inconsistent rows noted in the spec's errata
  20 (Table 5.2 DFL: std² ≠ var) and 21 (Table 5.5 nonlinear: std 2.8172 vs √var 2.8127).
* Table 5.6 (§5.4): "effect of increasing the gain on the mean error", one claim per gain.
* §5.4's two qualitative conclusions about the leader controllers.

The offset-point law (spec §3.5) is not in the thesis tables: it has no thesis values.
"""
from __future__ import annotations

from types import MappingProxyType

TESTS = ("T1", "T2", "T3", "T4")
THESIS_CONTROLLERS = ("approximate-linearization", "nonlinear", "cascaded", "kanayama", "dynamic-feedback")
STATISTICS = ("mean", "std", "var")

TABLE_OF_TEST = MappingProxyType({"T1": "Table 5.2", "T2": "Table 5.3", "T3": "Table 5.4", "T4": "Table 5.5"})

# (mean, std, var) per test and controller, in the order of THESIS_CONTROLLERS.
_ROWS = {
    "T1": ((0.1622, 0.7746, 0.6001), (0.1630, 0.7710, 0.5945), (0.5154, 0.6758, 0.4568),
           (3.3460, 2.9895, 8.9369), (0.0192, 0.0410, 0.00017)),
    "T2": ((0.0222, 0.1650, 0.0272), (0.0197, 0.1558, 0.0243), (0.0460, 0.0710, 0.0050),
           (0.2894, 0.5222, 0.2726), (0.0058, 0.0498, 0.0025)),
    "T3": ((0.2808, 0.2619, 0.0686), (0.3387, 0.4052, 0.1642), (0.6908, 0.6538, 0.4274),
           (1.0406, 0.8041, 0.6465), (0.2265, 0.6846, 0.4687)),
    "T4": ((0.9627, 2.4787, 6.1438), (1.3260, 2.8172, 7.9112), (9.7688, 0.7949, 0.6319),
           (11.3544, 1.3286, 1.7651), (1.0957, 2.8231, 7.9700)),
}

# ERROR_STATISTICS[test][controller] = {"mean": m, "std": s, "var": v}
ERROR_STATISTICS = MappingProxyType({
    test: MappingProxyType({controller: MappingProxyType(dict(zip(STATISTICS, values)))
                            for controller, values in zip(THESIS_CONTROLLERS, rows)})
    for test, rows in _ROWS.items()
})

# Table 5.6, in the thesis's order: (controller, gain, claimed effect of increasing it on the mean error).
# The claims are normalised to the vocabulary of nonholo.studies.sweep.TREND_WORDS; the thesis's
# wording is kept beside each one.
GAIN_EFFECTS = (
    ("approximate-linearization", "zeta", "decreases", "Decreases"),
    ("approximate-linearization", "b", "decreases", "Decreases"),
    ("nonlinear", "zeta", "decreases", "Decreases"),
    ("nonlinear", "b", "decreases", "Decreases"),
    ("cascaded", "c1", "decreases", "Decreases"),
    ("cascaded", "c2", "decreases", "Decreases"),
    ("cascaded", "c3", "increases", "Increases"),
    ("kanayama", "kx", "oscillates", "Oscillates"),
    ("kanayama", "ky", "increases", "Increases"),
    ("kanayama", "ktheta", "decreases", "Decreases"),
    ("dynamic-feedback", "kd1", "increases", "Increases"),
    ("dynamic-feedback", "kd2", "decreases", "Decreases"),
    ("dynamic-feedback", "kp1", "increases, then oscillates", "Increases, then oscillates (till a certain value)"),
    ("dynamic-feedback", "kp2", "decreases", "Decreases"),
)

# §5.4's conclusions about the leader controllers, quoted.
CONCLUSION_DFL_LOWEST = ("the full state linearized via dynamic feedback controller minimizes the mean of error "
                         "more rapidly for the given trajectories")
CONCLUSION_TEST4_FAILURES = ("the cascaded systems and stable tracking feedback controllers fail to track the "
                             "correct trajectory, when the robot and trajectory starting position are not the same "
                             "(test 4)")
