import numpy as np
import pytest

from nonholo import references
from nonholo.errors import InfeasibleReferenceError

THESIS = {"eight": 80 * np.pi, "line": 500.0, "sinusoid": 1000.0, "circle": 40 * np.pi}


def open_loop_path(ref, duration: float, intervals: int = 20_000, nodes: int = 6):
    """The unicycle driven open loop by the feedforward (v_d, ω_d) from q_d(0), at the edges
    of ``intervals`` equal intervals of [0, duration]. The unicycle is a chain of integrals —
    θ = θ_d(0) + ∫ω_d, x = x_d(0) + ∫v_d cos θ, y = y_d(0) + ∫v_d sin θ — each taken by
    Gauss–Legendre quadrature on every interval (θ at the nodes by a nested quadrature from the
    interval's start): an integrator independent of the simulator, error far below 1e-6 m."""
    row0 = ref.table([0.0])[0]
    edges = np.linspace(0.0, duration, intervals + 1)
    unit_nodes, unit_weights = np.polynomial.legendre.leggauss(nodes)

    def gauss(start, stop):   # nodes and weights of [start, stop], a new last axis
        half = (stop - start)[..., None] / 2.0
        return start[..., None] + half * (unit_nodes + 1.0), half * unit_weights

    def column(times, c):
        return ref.table(times.ravel())[:, c].reshape(times.shape)

    starts = edges[:-1]
    t_nodes, w_nodes = gauss(starts, edges[1:])                                  # (I, n)
    theta_edges = row0[7] + np.concatenate([[0.0], np.cumsum((column(t_nodes, 9) * w_nodes).sum(axis=1))])
    t_inner, w_inner = gauss(np.repeat(starts[:, None], nodes, axis=1), t_nodes)  # (I, n, n)
    theta = theta_edges[:-1, None] + (column(t_inner, 9) * w_inner).sum(axis=2)
    speed = column(t_nodes, 8)
    x = row0[1] + np.concatenate([[0.0], np.cumsum((speed * np.cos(theta) * w_nodes).sum(axis=1))])
    y = row0[2] + np.concatenate([[0.0], np.cumsum((speed * np.sin(theta) * w_nodes).sum(axis=1))])
    return edges, x, y, theta_edges


@pytest.mark.parametrize("kind", THESIS)
def test_open_loop_feedforward_reproduces_the_reference(kind):
    """Spec §2: the unicycle driven by (v_d, ω_d) from q_d(0) follows p_d to ≤ 1e-6 m."""
    ref = references.THESIS_TESTS[kind]()
    assert ref.default_duration == pytest.approx(THESIS[kind])
    t, x, y, theta = open_loop_path(ref, ref.default_duration)
    table = ref.table(t)
    assert np.max(np.hypot(x - table[:, 1], y - table[:, 2])) < 1e-6
    assert np.max(np.abs(np.angle(np.exp(1j * (theta - table[:, 7]))))) < 1e-6


def test_open_loop_check_sees_a_wrong_feedforward():
    # the quadrature above is sharp enough to catch a small error in ω_d
    ref = references.THESIS_TESTS["eight"]()
    table = ref.table

    class Skewed:
        def table(self, times):
            rows = table(times)
            rows[:, 9] *= 1.0 + 1e-6
            return rows

    t, x, y, _ = open_loop_path(Skewed(), ref.default_duration)
    rows = ref.table(t)
    assert np.max(np.hypot(x - rows[:, 1], y - rows[:, 2])) > 1e-5


def test_thesis_feedforward_values_at_zero():
    """Spec §2 test values v_d(0), θ_d(0); ω_d ≡ 0 on the line, 1/20 on the circle."""
    expected = {"eight": (0.559, 0.4636), "line": (1.0, np.pi / 2), "sinusoid": (np.sqrt(101), 1.4711),
                "circle": (0.5, np.pi / 2)}
    for kind, (v0, theta0) in expected.items():
        row = references.THESIS_TESTS[kind]().table([0.0])[0]
        assert row[8] == pytest.approx(v0, abs=5e-4) and row[7] == pytest.approx(theta0, abs=5e-5)
    assert np.allclose(references.line().table(np.linspace(0, 500, 11))[:, 9], 0.0)
    assert np.allclose(references.circle().table(np.linspace(0, 100, 11))[:, 9], 1 / 20)


def test_backward_direction_flips_speed_and_heading_not_turn_rate():
    fwd, bwd = references.circle().table([1.0])[0], references.circle(direction=-1).table([1.0])[0]
    assert bwd[8] == pytest.approx(-fwd[8]) and bwd[9] == pytest.approx(fwd[9])
    assert np.cos(bwd[7] - fwd[7]) == pytest.approx(-1.0)


def test_overridden_parameters_and_expression_agree():
    ref = references.circle(radius=3, period=20, center=(1, 2))
    same = references.expression("1 + 3*cos(2*pi*t/20)", "2 + 3*sin(2*pi*t/20)")
    t = np.linspace(0, 20, 7)
    assert np.allclose(ref.table(t), same.table(t), atol=1e-12)


def test_waypoint_spline_is_c2_and_passes_through_points():
    points = [[0, 0, 0], [2, 1, 1], [4, 3, 0], [6, 4, 2]]
    ref = references.waypoints(points)
    rows = ref.table([0.0, 2.0, 4.0, 6.0])
    assert np.allclose(rows[:, 1:3], np.array(points)[:, 1:])
    eps = 1e-7
    around_knot = ref.flat_outputs(np.array([2 - eps, 2 + eps]))
    assert np.allclose(around_knot[:, 0], around_knot[:, 1], atol=1e-5)  # p, ṗ, p̈ continuous at a knot
    with pytest.raises(ValueError, match="strictly increasing"):
        references.waypoints([[0, 0, 0], [0, 1, 1]])


def test_vanishing_speed_is_found_between_grid_points():
    ref = references.expression("(t - 3.0012345)^3", "(t - 3.0012345)^2")
    with pytest.raises(InfeasibleReferenceError, match=r"t = 3\.0012"):
        ref.check_speed(0.0, 10.0)
    references.eight().check_speed(0.0, 80 * np.pi)  # min speed 0.174 m/s: feasible


@pytest.mark.parametrize("x, y, zero", [("(t+1) - sin(t+1)", "1 - cos(t+1)", 2 * np.pi - 1),   # cycloid cusp
                                        ("(t-5.283185)^2", "(t-5.283185)^3/10", 5.283185),
                                        ("(t-4.123456789)^2", "(t-4.123456789)^3/10", 4.123456789)])
def test_a_speed_that_vanishes_linearly_between_grid_points_is_found(x, y, zero):
    """|ṗ_d| ≈ |p̈_d| |t − t*| near a rest point: the minimizer's √eps·|t| in time left a
    minimum ~1e-8 of p̈_d, above the 1e-9 acceptance, and the cusp was missed; the tangent
    line's closest approach to zero finds it to the last digits."""
    found = references.expression(x, y).vanishing_speed_times(0.0, 10.0)
    assert len(found) == 1 and found[0] == pytest.approx(zero, abs=1e-12)
    near_miss = references.expression("(t-5.0000123)^2", "1e-6*t")   # min speed 1e-6, 1e-7 of the peak
    assert near_miss.vanishing_speed_times(0.0, 10.0) == []


def test_table_rows_are_the_feedforward_formulas_bit_for_bit():
    """``table_rows`` (one compiled pass) gives the numbers of the spec's formulas written as
    numpy array expressions, to the bit: speeds that vanish (ω_d = 0 there), non-finite
    derivatives, both directions, and the angles of signed zeros."""
    from nonholo.references.feedforward import feedforward, table_rows

    rng = np.random.default_rng(7)
    flat = rng.normal(scale=3.0, size=(6, 4000))
    flat[2:4, :40] = 0.0                      # vanishing speed
    flat[2:4, 40:44] = [[-0.0, 0.0, -0.0, 0.0], [0.0, -0.0, -0.0, 0.0]]
    flat[4, 44], flat[2, 45], flat[3, 46] = np.nan, np.inf, -np.inf
    t = np.arange(flat.shape[1]) * 0.01
    for direction in (1, -1):
        dx, dy, ddx, ddy = flat[2:]
        speed_sq = dx * dx + dy * dy
        with np.errstate(invalid="ignore", divide="ignore"):
            omega = np.where(speed_sq > 0.0, (dx * ddy - dy * ddx) / np.where(speed_sq > 0.0, speed_sq, 1.0), 0.0)
        expected = np.column_stack([t, flat.T, np.arctan2(direction * dy, direction * dx),
                                    direction * np.sqrt(speed_sq), omega])
        rows = table_rows(t, flat, direction)
        assert rows.tobytes() == expected.tobytes()
        theta, v, w = feedforward(dx.reshape(40, 100), dy.reshape(40, 100), ddx.reshape(40, 100),
                                  ddy.reshape(40, 100), direction)
        assert theta.shape == (40, 100) and v.tobytes() == expected[:, 8].tobytes()
        assert theta.ravel().tobytes() == expected[:, 7].tobytes() and w.ravel().tobytes() == omega.tobytes()
    theta, v, w = feedforward(3.0, 4.0, 0.0, 1.0)   # scalars give scalars
    assert np.ndim(theta) == 0 and (theta, v, w) == (np.arctan2(4.0, 3.0), 5.0, 3.0 / 25.0)
    with pytest.raises(ValueError, match="flat outputs"):   # never read past the arrays
        table_rows(np.arange(5.0), flat[:, :3])


def test_formula_tables_take_sin_and_cos_of_each_argument_once():
    """sin(a) and cos(a) of one argument are one pair, computed once per table (the SIMD
    ``array_sincos``), and the table matches numpy's sin and cos to rounding."""
    import inspect

    ref = references.expression("3*cos(t/7) + sin(2*t)", "sin(t/7)**2 - cos(2*t) + sin(t)")
    source = inspect.getsource(ref._evaluate)
    assert source.count("sin_cos_pair(") == 3   # t/7, 2*t and t
    t = np.linspace(0.0, 60.0, 2001)
    rows = ref.table(t)
    x = 3 * np.cos(t / 7) + np.sin(2 * t)
    dy = 2 * np.sin(t / 7) * np.cos(t / 7) / 7 + 2 * np.sin(2 * t) + np.cos(t)
    ddx = -3 * np.cos(t / 7) / 49 - 4 * np.sin(2 * t)
    assert np.allclose(rows[:, 1], x, rtol=0, atol=1e-14) and np.allclose(rows[:, 4], dy, rtol=0, atol=1e-14)
    assert np.allclose(rows[:, 5], ddx, rtol=0, atol=1e-14)
