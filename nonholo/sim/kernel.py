"""The one compiled kernel: fixed-step RK4 of a graph of unicycles — roots under a tracking or
posture law, followers under an l–φ or l–l formation law — for a batch of copies at once.

Data layout (structure of arrays, the batch axis innermost so that loops over it vectorize).
R robots of one graph, listed so that ``order`` visits parents before children; B copies
(batch members) of that graph, which share its structure and differ in fields and starts:

* ``state``   (4, R, B): x, y, θ, ξ (ξ = the law's own state, e.g. the dynamic compensator)
* ``fields``  (MAX_FIELDS, R, B): a root's law fields (its gain namedtuple, goal first for a
  posture law); a follower's k1, k2, d
* ``limits``  (2, R, B): |v| ≤ v_max, |ω| ≤ ω_max (inf = no limit)
* ``rows``    (r, 10): the reference at every stage time (``REF_COLUMNS``); output step k
  with m_k sub-steps owns rows ``row_start[k] … row_start[k] + 2 m_k`` (times t_k + j h/2,
  h = dt/m_k), the last one shared with step k + 1
* ``targets`` (r, 6, R): follower targets z1_d, z2_d and their rates at the same stage times
  (one row when no follower's targets change), then z1_d, z2_d just after each time (the first
  stage of a sub-step reads these: ``nonholo.sim.targets.TABLE_COLUMNS``); ``offsets``
  (2, R, B) per-copy constant offsets added to z1_d, z2_d (sweeps of l, φ)
* topology: ``kinds`` (R,) ``ROOT_A``/``ROOT_B`` (root under law A or B), ``SEPARATION_BEARING``,
  ``SEPARATION_SEPARATION``; ``parents`` (2, R); ``feeds`` (R,) 1 where a robot has children
* ``branch``  (R, B): each l–φ bearing on its continuous 2π branch
* ``stats``   (STAT_COUNT, R, B) running statistics sampled at t_k = k·dt; ``pair_stats``
  (PAIR_COUNT, B) the closest pair of each copy; ``d_max`` (B,) its largest castor offset
* ``record``  (rows, N + 1, R, B), or (rows, 0, R, B) for statistics only: ``REC_ROBOT_COUNT``
  rows of every robot, then, in graphs with followers only, ``REC_LINK_COUNT`` rows of a
  follower's link (``record_rows``)
* ``held``    (HELD_COUNT, R, B): commands held between control instants (sampled data)
* ``step_rate`` (N + 1,): the fastest rate met during each output step, for sub-step planning:
  in graphs with followers and of posture roots |ω| of every robot and |ξ̇/ξ| of speed
  compensators at every stage (``stage_rate``), for tracking roots |ω| at each sub-step's
  first stage (``tracking_rate``); lone tracking roots under continuous-time control also
  keep their own largest rate × step in their statistics (``STEP_RATE``, ``wide_substep``)

Continuous-time control evaluates every law at every RK4 stage. Each robot keeps its four
stages in registers; a robot with children writes its stage poses and commands to a small
scratch array, from which its children read them at the same stage (spec
follower-posture.md §4: parents first, their *computed* commands). Sampled-data control
(``hold_every`` > 0, spec fleet.md §2) evaluates every law once per control instant, parents
first, and integrates each robot with its command held.

Inside the loops over the batch only functions of scalars and tuples are called (the kernel's
own helpers inlined by numba, the laws inlined by LLVM): a called function that writes through
an array argument reference-counts it on every iteration, which stops vectorization; and
copy indices are never negative as LLVM sees them (a loop from 0, or unsigned bounds),
or the wrap-around of negative indices it keeps stops vectorization too. Lone roots under
continuous-time control sample at t_k the command of the first stage of the RK4 step from
t_k (the law at the same state and reference row), not a fifth evaluation. The
kernel mutates ``state``, ``branch``, ``stats``, ``pair_stats``, ``record``, ``held`` and
``step_rate``, and can be resumed (``k_start``, ``k_stop``) so that callers can show progress.
The loops over the batch are compiled per pair of root laws and per "has followers"
(``make_kernel``); lone roots run one at a time (``run_alone``: single runs, scoring) by code
compiled once for every law, which calls the law through its address
(``nonholo.sim.lawcall``). Everything is cached on disk by numba.
"""
from __future__ import annotations

import math
from collections import namedtuple

import llvmlite.binding
import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core.imputils import impl_ret_borrowed
from numba.extending import intrinsic
from numba.np.arrayobj import populate_array

from nonholo.control.declare import GOAL_FIELDS
from nonholo.control.formation import separation_bearing_law, separation_separation_law
from nonholo.models.formation_geometry import link_geometry
from nonholo.models.formation_kinematics import bearing_rate, separation_rate
from nonholo.models.unicycle import unicycle_rates
from nonholo.numerics import ROTATION_MAX, rotated_sincos, sincos, wrap_angle
from nonholo.references.feedforward import REF_THETA, REF_X, REF_Y
from nonholo.sim.lawcall import (FIELDS_SIZE, REF_SIZE, law_at_address, law_entry, row_address, stable_cache_identity,
                                 stack_copy)

# The robot loops read and write many rows of distinct arrays, which LLVM cannot prove
# disjoint; past its default of 8 run-time overlap checks it refuses to vectorize
# ("too many memory checks needed"). These limits only allow more such checks (a few
# comparisons per loop, not per robot); the options are process-wide.
llvmlite.binding.set_option("nonholo", "-runtime-memory-check-threshold=256")
llvmlite.binding.set_option("nonholo", "-vectorize-memory-check-threshold=1024")
# Laws are compiled once each, as functions of their own (numba-level inlining re-typed and
# re-lowered a law at each of its ten call sites: a minute per kernel on a fresh install);
# LLVM inlines them into the kernel's loops instead, which vectorization needs. Its default
# threshold (a few hundred instructions) would leave a long law as a call inside the loop
# over the batch: raise it.
llvmlite.binding.set_option("nonholo", "-inline-threshold=100000")


def _noalias() -> dict:
    """``noalias=True`` for ``njit``, where this numba has it. numba marks the array data
    pointers of such a function ``noalias`` (its compiler flag ``noalias``, which ``njit`` does
    not map from an option: mapped here), so that LLVM vectorizes its loops without run-time
    overlap checks — the batch loop of lone roots compiles in half the time. Only for a
    function whose arrays are distinct objects at every call (``run_roots``)."""
    try:
        from numba.core.compiler import Flags
        from numba.core.cpu import CPUTargetOptions
        from numba.core.options import TargetOptions
    except ImportError:
        return {}
    if not hasattr(Flags, "noalias"):
        return {}
    if not hasattr(CPUTargetOptions, "noalias"):
        CPUTargetOptions.noalias = TargetOptions.Mapping("noalias")
    return {"noalias": True}


NOALIAS = _noalias()

ROOT_A, ROOT_B, SEPARATION_BEARING, SEPARATION_SEPARATION = range(4)
MAX_FIELDS = FIELDS_SIZE   # a root's law fields (at most MAX_LAW_FIELDS); a follower uses 3
K1, K2, OFFSET_D = 0, 1, 2  # a follower's fields

(E_MEAN, E_M2, E_SQ, E_MAX, E_FINAL, H_SUM, H_SQ, H_MAX, H_FINAL, V_PEAK, V_PEAK_T, W_PEAK, W_PEAK_T, V_SQ, W_SQ,
 SAT_V, SAT_W, SINGULAR, FIRST_SINGULAR, SAT_ANY, MIN_SIN, MIN_SIN_T, NEAR, NEAR_T, NEAR_WHO, BELOW_2D, SIN_LAST,
 SIN_CROSSINGS, WATCHDOG_STOPS, WATCHDOG_STOPPED, STEP_RATE) = range(31)
STAT_COUNT = 31   # (WATCHDOG_*: a follower's watchdog under a link model, counted by nonholo.sim.linkstep;
# STEP_RATE: a tracking root's own check of its sub-step plan, ``wide_substep``)
ROBOT_STATS = SAT_ANY + 1   # the statistics of every robot (``add_sample``); the rest: formations
# ``robot_stats``, ``add_sample`` and ``store_stats`` hold them as a tuple in this order (SAT_ANY:
# samples where v or ω or both were clipped).
assert (E_MEAN, E_M2, E_SQ, E_MAX, E_FINAL, H_SUM, H_SQ, H_MAX, H_FINAL, V_PEAK, V_PEAK_T, W_PEAK, W_PEAK_T, V_SQ, W_SQ,
        SAT_V, SAT_W, SINGULAR, FIRST_SINGULAR, SAT_ANY) == tuple(range(ROBOT_STATS))
# Lone roots under continuous-time control with fewer copies than this run one at a time
# (``Kernel.alone``), not in loops over the batch: a loop entered for one or two copies costs
# LLVM's run-time overlap checks (tens of comparisons) at every step.
ALONE_BELOW = 4
# The most RK4 sub-steps per output step a plan asks for (``nonholo.sim.simulator.measured_plan``).
MAX_SUBSTEPS = 1000
# Which rates a lone root's time loop measures (``run_alone``): none, every RK4 stage's, or
# the first stage's of each sub-step.
MEASURE_NONE, MEASURE_STAGES, MEASURE_FIRST_STAGE = 0, 1, 2
# Batches of lone roots under continuous-time control run this many copies at a time through
# the whole time loop (``Kernel.roots``): their state and statistics stay in the core's caches.
ROOTS_CHUNK = 128
KEPT_COUNT = 9   # what ``roots`` keeps of a copy's sample at t_k: x, y, θ, ξ, v, ω, singular, sat v, sat ω
SLOPE_COUNT = 4   # what ``roots`` keeps of a copy's RK4 stage for the next ones: k1, k2, k3 (ẋ, ẏ, θ̇, ξ̇) each
RATE_ROW = SLOPE_COUNT   # and in the row after: k1's stage rate (the plan's), k2's and k3's |θ̇| (``stage_headings``)
# ``roots`` runs a chunk of copies in one workspace (``workspace_views``): the rows of its state,
# statistics, fields and limits (copied in and out by ``roots``), then scratch rows: the sample
# at t_k, the stage rates k1, k2, k3 (each with a RATE_ROW), and sin θ and cos θ at stage 1 and
# at the stage being computed (``HEADING_ROWS``). Rows of
# ROOTS_CHUNK + 8 columns (a row 17 cache lines long, not a power of two: rows 1 KiB apart
# shared the L1 cache's sets, and the kernel ran a third slower), the first 64-byte aligned.
HEADING_ROWS = 4   # sin θ, cos θ at stage 1; sin θ, cos θ at the stage (``stage_headings``)
WORKSPACE_COUNTS = (4, STAT_COUNT, MAX_FIELDS, 2, KEPT_COUNT, SLOPE_COUNT + 1, SLOPE_COUNT + 1, SLOPE_COUNT + 1,
                    HEADING_ROWS)
WORKSPACE_FIRST = tuple(int(n) for n in np.cumsum((0,) + WORKSPACE_COUNTS[:-1]))
WORKSPACE_ROWS = sum(WORKSPACE_COUNTS)
WORKSPACE_WIDTH = ROOTS_CHUNK + 8
WORKSPACE_KEPT = 4   # the first four (state, statistics, fields, limits) hold the simulator's arrays
CLOSEST, CLOSEST_T, CLOSEST_I, CLOSEST_J, BELOW_ANY = range(5)
PAIR_COUNT = 5
(REC_X, REC_Y, REC_THETA, REC_XI, REC_V, REC_OMEGA, REC_ERR1, REC_ERR2, REC_SINGULAR, REC_SATURATED, REC_OUT1,
 REC_OUT2, REC_RATE1, REC_RATE2, REC_SIN_GAMMA) = range(15)
REC_COUNT = 15
# ``record_row`` and ``store_record`` hold a robot's rows in this order, ``store_link_record`` a
# follower's link rows after them; records of graphs without followers have the robot rows only
# (the link rows would be zeros: a third of a recorded lone root). See ``record_rows``.
REC_ROBOT_COUNT = REC_SATURATED + 1
REC_LINK_COUNT = REC_COUNT - REC_ROBOT_COUNT
HELD_V, HELD_OMEGA, HELD_XI_DOT, HELD_SINGULAR, HELD_SAT_V, HELD_SAT_OMEGA = range(6)
HELD_COUNT = 6
# What one evaluation at an instant gives per robot (``instant`` array rows).
(I_V, I_OMEGA, I_XI_DOT, I_SINGULAR, I_SAT_V, I_SAT_OMEGA, I_OUT1, I_OUT2, I_ERR1, I_ERR2, I_RATE1, I_RATE2,
 I_SIN_GAMMA) = range(13)
INSTANT_COUNT = 13
# The held commands are the first HELD_COUNT rows of an instant, in the same order.
assert (HELD_V, HELD_OMEGA, HELD_XI_DOT, HELD_SINGULAR, HELD_SAT_V, HELD_SAT_OMEGA) == \
    (I_V, I_OMEGA, I_XI_DOT, I_SINGULAR, I_SAT_V, I_SAT_OMEGA)

# "contract" lets LLVM fuse a*b + c into one FMA instruction (deterministic, and more
# accurate); no other fast-math relaxations, so NaN/inf semantics and ordering stay IEEE.
_OPTIONS = dict(cache=True, error_model="numpy", fastmath={"contract"})


def record_rows(followers: bool) -> int:
    """The rows of a record of a graph with followers (``REC_COUNT``) or without (``REC_ROBOT_COUNT``)."""
    return REC_COUNT if followers else REC_ROBOT_COUNT


def new_stats(robots: int, batch: int) -> tuple[np.ndarray, np.ndarray]:
    """Empty running statistics ``(stats, pair_stats)``."""
    stats = np.zeros((STAT_COUNT, robots, batch))
    stats[[FIRST_SINGULAR, MIN_SIN, NEAR]] = np.inf
    stats[NEAR_WHO] = -1.0
    pair_stats = np.zeros((PAIR_COUNT, batch))
    pair_stats[CLOSEST] = np.inf
    pair_stats[[CLOSEST_I, CLOSEST_J]] = -1.0
    return stats, pair_stats


@njit(inline="always", **_OPTIONS)
def field_row(fields, r, b):
    """A robot's fields as a tuple of scalars (laws take the first n, by name)."""
    return (fields[0, r, b], fields[1, r, b], fields[2, r, b], fields[3, r, b], fields[4, r, b], fields[5, r, b],
            fields[6, r, b], fields[7, r, b], fields[8, r, b], fields[9, r, b])


def _workspace_rows(first: int, count: int, robot_axis: bool):
    """A compiled function of a ``roots`` workspace (``WORKSPACE_ROWS`` × ``WORKSPACE_WIDTH``,
    C order): its rows first … first + count − 1 as an array of their own, (count, 1,
    ``WORKSPACE_WIDTH``) with ``robot_axis`` (indexed as the simulator's [row, robot, copy]
    arrays), else (count, ``WORKSPACE_WIDTH``). Its shape and strides are constants of the
    compiled code, where numpy-style slicing and reshaping would leave them run-time values:
    every row of every such array then lies at a constant offset from the workspace's one
    pointer, and the time loop addresses them all from one register (with a pointer per
    row, most were kept on the stack and loaded again at every use)."""
    shape = (count, 1, WORKSPACE_WIDTH) if robot_axis else (count, WORKSPACE_WIDTH)
    steps = (WORKSPACE_WIDTH * 8, WORKSPACE_WIDTH * 8, 8) if robot_axis else (WORKSPACE_WIDTH * 8, 8)
    result = types.Array(types.float64, len(shape), "C")

    @intrinsic
    def rows_of(typingctx, workspace):
        def codegen(context, builder, signature, args):
            source = context.make_array(signature.args[0])(context, builder, args[0])
            view = context.make_array(result)(context, builder)
            intp = context.get_value_type(types.intp)
            populate_array(view, data=builder.gep(source.data, [ir.Constant(intp, first * WORKSPACE_WIDTH)]),
                           shape=[ir.Constant(intp, n) for n in shape],
                           strides=[ir.Constant(intp, n) for n in steps], itemsize=ir.Constant(intp, 8),
                           meminfo=source.meminfo)
            return impl_ret_borrowed(context, builder, result, view._getvalue())
        return result(workspace), codegen
    return rows_of


# one view of the workspace for each of its parts, the first four indexed [row, robot, copy]
_WORKSPACE_VIEWS = tuple(_workspace_rows(first, count, part < WORKSPACE_KEPT)
                         for part, (first, count) in enumerate(zip(WORKSPACE_FIRST, WORKSPACE_COUNTS)))
_VIEW_0, _VIEW_1, _VIEW_2, _VIEW_3, _VIEW_4, _VIEW_5, _VIEW_6, _VIEW_7, _VIEW_8 = _WORKSPACE_VIEWS


@njit(inline="always", **_OPTIONS)
def workspace_views(workspace):
    """The parts of a ``roots`` workspace as the arrays its time loop reads: state, stats,
    fields and limits (robot 0: one robot, ``ROOTS_CHUNK`` copies), the sample, k1, k2, k3
    and the stage's sin θ and cos θ."""
    return (_VIEW_0(workspace), _VIEW_1(workspace), _VIEW_2(workspace), _VIEW_3(workspace), _VIEW_4(workspace),
            _VIEW_5(workspace), _VIEW_6(workspace), _VIEW_7(workspace), _VIEW_8(workspace))


def new_workspace() -> np.ndarray:
    """A zeroed ``roots`` workspace (``WORKSPACE_ROWS`` × ``WORKSPACE_WIDTH``), its first row
    64-byte aligned, and so every row (numpy aligns to 16 bytes: a 512-bit load then spans
    two cache lines)."""
    size = WORKSPACE_ROWS * WORKSPACE_WIDTH
    raw = np.zeros(size + 8)
    skip = (-raw.ctypes.data % 64) // 8
    return raw[skip:skip + size].reshape(WORKSPACE_ROWS, WORKSPACE_WIDTH)


@njit(inline="always", **_OPTIONS)
def row_values(rows, r):
    """Reference row r as a tuple of scalars (laws index it like an array)."""
    return (rows[r, 0], rows[r, 1], rows[r, 2], rows[r, 3], rows[r, 4], rows[r, 5], rows[r, 6], rows[r, 7],
            rows[r, 8], rows[r, 9])


@njit(inline="always", **_OPTIONS)
def saturate(v_raw, omega_raw, v_max, omega_max):
    """Actuator limits: clipped (v, ω) and 1.0 flags where each limit acted. abs(nan) >
    limit is False: a non-finite command is not "saturation" (the simulator reports
    divergence separately)."""
    v = min(max(v_raw, -v_max), v_max)
    omega = min(max(omega_raw, -omega_max), omega_max)
    return v, omega, 1.0 if abs(v_raw) > v_max else 0.0, 1.0 if abs(omega_raw) > omega_max else 0.0


@njit(inline="always", **_OPTIONS)
def continuous_bearing(raw, previous):
    """φ on the 2π branch nearest ``previous`` (spec follower-posture.md §2.5)."""
    return previous + wrap_angle(raw - previous)


def law_command(law, gains, x, y, theta, sin_t, cos_t, xi, ref, v_max, omega_max):
    """A root's saturated command at one state, sin θ and cos θ given: (v, ω, ξ̇, singular,
    sat v, sat ω)."""
    v_raw, omega_raw, xi_dot, singular = law(x, y, theta, cos_t, sin_t, xi, ref, gains)
    v, omega, sat_v, sat_w = saturate(v_raw, omega_raw, v_max, omega_max)
    return v, omega, xi_dot, singular, sat_v, sat_w


def root_command(law, gains, x, y, theta, xi, ref, v_max, omega_max):
    """A root's saturated command at one state: (v, ω, ξ̇, singular, sat v, sat ω, cos θ, sin θ)."""
    sin_t, cos_t = sincos(theta)
    return law_command(law, gains, x, y, theta, sin_t, cos_t, xi, ref, v_max, omega_max) + (cos_t, sin_t)


@njit(cache=True, error_model="numpy", fastmath=False)   # followers: IEEE arithmetic (see make_kernel)
def bearing_command(x, y, theta, px, py, ptheta, pv, pomega, branch, l_d, phi_d, l_rate, phi_rate, k1, k2, d,
                    v_max, omega_max):
    """An l–φ follower's saturated command and link state: (v, ω, sat v, sat ω, cos θ, sin θ,
    l, φ, l̇, φ̇) with φ on the branch nearest ``branch``."""
    sin_t, cos_t = sincos(theta)
    separation, raw, cos_phi, sin_phi, cos_g, sin_g = link_geometry(px, py, ptheta, x, y, cos_t, sin_t, theta, d)
    bearing = continuous_bearing(raw, branch)
    v_raw, omega_raw = separation_bearing_law(separation, bearing, cos_phi, sin_phi, cos_g, sin_g, pv, pomega, l_d,
                                              phi_d, l_rate, phi_rate, k1, k2, d)
    v, omega, sat_v, sat_w = saturate(v_raw, omega_raw, v_max, omega_max)
    l_dot = separation_rate(v, omega, pv, d, cos_phi, cos_g, sin_g)
    phi_dot = bearing_rate(v, omega, pv, pomega, separation, d, sin_phi, cos_g, sin_g)
    return v, omega, sat_v, sat_w, cos_t, sin_t, separation, bearing, l_dot, phi_dot


@njit(cache=True, error_model="numpy", fastmath=False)   # followers: IEEE arithmetic (see make_kernel)
def pair_command(x, y, theta, p1x, p1y, p1theta, p1v, p2x, p2y, p2theta, p2v, l1_d, l2_d, l1_rate, l2_rate, k1, k2,
                 d, sin_floor, v_max, omega_max):
    """An l–l follower's saturated command and link state: (v, ω, sat v, sat ω, singular,
    cos θ, sin θ, l1, l2, l̇1, l̇2, sin(γ1 − γ2))."""
    sin_t, cos_t = sincos(theta)
    l1, _, cos_phi_1, _, cos_g1, sin_g1 = link_geometry(p1x, p1y, p1theta, x, y, cos_t, sin_t, theta, d)
    l2, _, cos_phi_2, _, cos_g2, sin_g2 = link_geometry(p2x, p2y, p2theta, x, y, cos_t, sin_t, theta, d)
    v_raw, omega_raw, sin_difference, singular = separation_separation_law(
        l1, l2, cos_phi_1, cos_phi_2, cos_g1, sin_g1, cos_g2, sin_g2, p1v, p2v, l1_d, l2_d, l1_rate, l2_rate, k1, k2,
        d, sin_floor)
    v, omega, sat_v, sat_w = saturate(v_raw, omega_raw, v_max, omega_max)
    l1_dot = separation_rate(v, omega, p1v, d, cos_phi_1, cos_g1, sin_g1)
    l2_dot = separation_rate(v, omega, p2v, d, cos_phi_2, cos_g2, sin_g2)
    return v, omega, sat_v, sat_w, singular, cos_t, sin_t, l1, l2, l1_dot, l2_dot, sin_difference


@njit(cache=True, error_model="numpy", fastmath=False)
def fill_stage_times(dt, plan, k0, k1, times):
    """``times`` (``plan``'s rows of output steps k0 … k1 − 1, then the sample at k1): the
    j-th half sub-step of output step k at k·dt + j·(dt/(2m)), m = plan[k], then k1·dt.
    IEEE arithmetic, the numbers numpy gives for the same expressions; one pass, where
    numpy's broadcast sum over rows of two (one sub-step) took 5 ns a time."""
    row = 0
    for k in range(k0, k1):
        rows = 2 * plan[k]
        half_substep = dt / rows
        start = k * dt
        for j in range(rows):
            times[row] = start + j * half_substep
            row += 1
    times[row] = k1 * dt


@njit(inline="always", **_OPTIONS)
def rk4_sum(value, sixth, k1, k2, k3, k4):
    """The classical RK4 combination value + h/6 (k1 + 2 k2 + 2 k3 + k4)."""
    return value + sixth * (k1 + 2.0 * (k2 + k3) + k4)


@njit(inline="always", **_OPTIONS)
def unicycle_step(x, y, theta, xi, v, omega, xi_dot, h):
    """One RK4 step of the unicycle under a command held over the step (exact for ξ)."""
    half = 0.5 * h
    s1, c1 = sincos(theta)
    s2, c2 = sincos(theta + half * omega)
    s4, c4 = sincos(theta + h * omega)
    sixth = h / 6.0
    return (rk4_sum(x, sixth, v * c1, v * c2, v * c2, v * c4), rk4_sum(y, sixth, v * s1, v * s2, v * s2, v * s4),
            theta + h * omega, xi + h * xi_dot)


@njit(inline="always", **_OPTIONS)
def parent_stage(stage_pose, stage_command, s, p, b):
    """(x, y, θ, v, ω) of robot p at RK4 stage s (zeros for no parent, p < 0)."""
    if p < 0:
        return 0.0, 0.0, 0.0, 0.0, 0.0
    return (stage_pose[s, 0, p, b], stage_pose[s, 1, p, b], stage_pose[s, 2, p, b], stage_command[s, 0, p, b],
            stage_command[s, 1, p, b])


@njit(**_OPTIONS)
def store_stages(stage_pose, stage_command, r, b, s0, s1, s2, s3):
    """Keep a parent's four stage poses and commands (x, y, θ, v, ω) for its children."""
    for s, values in enumerate((s0, s1, s2, s3)):
        stage_pose[s, 0, r, b], stage_pose[s, 1, r, b], stage_pose[s, 2, r, b] = values[0], values[1], values[2]
        stage_command[s, 0, r, b], stage_command[s, 1, r, b] = values[3], values[4]


# ``root_command`` and ``root_rk4`` are compiled as functions of their own, once per law
# (LLVM inlines them into the kernels' loops): numba-level inlining would re-type and copy a
# root's command at every call site of every kernel, most of a kernel's compile time. Two
# variants of each, one per kernel kind (lone roots fuse multiply-adds, graphs with
# followers and the solver-step study do not, see ``make_kernel``); not cached on their own
# (the kernels that call them are, with their code inside).
# ``law_command`` (called by both, and by ``Kernel.roots`` with sin/cos of its own) has no
# arithmetic of its own to fuse, only the limits' comparisons: one variant serves both.
# ``plant_rates`` is the model's ``unicycle_rates`` with IEEE products, for every root's RK4
# stage: without limits (``Kernel.roots``' loop that calls the law itself) v is the law's own
# value, and LLVM merges the plant's v·cos θ with the same product in the law (dynamic
# feedback: v = ξ, and the law's ξ·cos θ), one multiply fewer; the law's products are not
# fused into multiply-adds, and so the plant's are not either, in every lone root's code
# alike: a copy in a batch, with limits or without, and a robot alone give the same numbers
# to the last bit (for laws with IEEE arithmetic, ``@control_law``'s default: a law that fuses
# its own products can differ in its last bits).
# ``stage_sincos`` and ``stage_rotation`` are ``sincos`` and ``rotated_sincos`` as the lone
# roots' kernels compile them (fused multiply-adds: the same numbers as in their
# ``root_command`` and ``root_rk4``), for ``Kernel.roots``'s time loop: inlined by numba, their
# code was copied into that loop at each call site (1.5 s more of a fresh install's
# compiling per law).
law_command = njit(error_model="numpy", fastmath=False)(law_command)
plant_rates = njit(error_model="numpy", fastmath=False)(unicycle_rates.py_func)
stage_sincos = njit(error_model="numpy", fastmath={"contract"})(sincos.py_func)
stage_rotation = njit(error_model="numpy", fastmath={"contract"})(rotated_sincos.py_func)
root_command_exact = njit(error_model="numpy", fastmath=False)(root_command)
root_command = njit(error_model="numpy", fastmath={"contract"})(root_command)
for _function, _name in ((law_command, "law_command"), (plant_rates, "plant_rates"),
                         (stage_sincos, "stage_sincos"),
                         (stage_rotation, "stage_rotation"), (root_command_exact, "root_command_exact"),
                         (root_command, "root_command")):
    _function._set_uuid(f"{__name__}.{_name}")


@njit(inline="always", error_model="numpy")
def rotated_heading(sin_a, cos_a, d, angle):
    """sin and cos of an RK4 stage's heading ``angle`` = a + d, from the first stage's sin a
    and cos a: rotated (``rotated_sincos``) where |d| ≤ ``ROTATION_MAX``, else in full. The
    rule of every lone root's stages 2–4 under continuous-time control (``root_rk4_fused``,
    ``Kernel.roots``: the same numbers). d is h/2·ω or h·ω: in range while h·|ω| ≤ 1/8 at
    stage 4 (1/4 at stages 2 and 3); tracking plans allow h·|ω| up to ``STABLE_STEP_FACTOR``
    (0.5), so fast turns (far starts, coarse steps) take the full sin/cos, at its cost."""
    if abs(d) <= ROTATION_MAX:
        return rotated_sincos(sin_a, cos_a, d)
    return sincos(angle)


@njit(inline="always", error_model="numpy")
def full_heading(sin_a, cos_a, d, angle):
    """sin and cos of an RK4 stage's heading ``angle``, in full (graphs with followers and the
    solver-step study: IEEE arithmetic throughout)."""
    return sincos(angle)


def _make_root_rk4(heading, fastmath):
    def root_rk4(law, gains, x, y, theta, xi, r0, r1, r2, h, v_max, omega_max):
        """One classical RK4 step of a root under ``law``, the four stages in registers: the
        new (x, y, θ, ξ), then each stage's (x, y, θ, ξ, ξ̇, v, ω) for children and rate
        measures; the first stage's also ends with its (singular, sat v, sat ω): it is the
        command at the step's start, which the sample at t_k takes. Stages 2–4 take their
        sin θ and cos θ from ``heading`` (``rotated_heading`` or ``full_heading``)."""
        half = 0.5 * h
        s1, co1 = sincos(theta)
        v1, w1, e1, singular, sat_v, sat_w = law_command(law, gains, x, y, theta, s1, co1, xi, r0, v_max, omega_max)
        a1, b1, c1 = plant_rates(v1, w1, co1, s1)
        x2, y2, t2, xi2 = x + half * a1, y + half * b1, theta + half * c1, xi + half * e1
        s, co = heading(s1, co1, half * c1, t2)
        v2, w2, e2, _, _, _ = law_command(law, gains, x2, y2, t2, s, co, xi2, r1, v_max, omega_max)
        a2, b2, c2 = plant_rates(v2, w2, co, s)
        x3, y3, t3, xi3 = x + half * a2, y + half * b2, theta + half * c2, xi + half * e2
        s, co = heading(s1, co1, half * c2, t3)
        v3, w3, e3, _, _, _ = law_command(law, gains, x3, y3, t3, s, co, xi3, r1, v_max, omega_max)
        a3, b3, c3 = plant_rates(v3, w3, co, s)
        x4, y4, t4, xi4 = x + h * a3, y + h * b3, theta + h * c3, xi + h * e3
        s, co = heading(s1, co1, h * c3, t4)
        v4, w4, e4, _, _, _ = law_command(law, gains, x4, y4, t4, s, co, xi4, r2, v_max, omega_max)
        a4, b4, c4 = plant_rates(v4, w4, co, s)
        sixth = h / 6.0
        return ((rk4_sum(x, sixth, a1, a2, a3, a4), rk4_sum(y, sixth, b1, b2, b3, b4),
                 rk4_sum(theta, sixth, c1, c2, c3, c4), rk4_sum(xi, sixth, e1, e2, e3, e4)),
                (x, y, theta, xi, e1, v1, w1, singular, sat_v, sat_w), (x2, y2, t2, xi2, e2, v2, w2),
                (x3, y3, t3, xi3, e3, v3, w3), (x4, y4, t4, xi4, e4, v4, w4))

    return njit(error_model="numpy", fastmath=fastmath)(root_rk4)


root_rk4_fused = _make_root_rk4(rotated_heading, {"contract"})
root_rk4_exact = _make_root_rk4(full_heading, False)
root_rk4_fused._set_uuid(f"{__name__}.root_rk4_fused")
root_rk4_exact._set_uuid(f"{__name__}.root_rk4_exact")


@njit(inline="always", **_OPTIONS)
def stage_rate(stage, xi_speed):
    """The fastest rate of one root stage: |ω|, and |ξ̇/ξ| of a speed compensator."""
    return max(abs(stage[6]), xi_speed * abs(stage[4]) / max(abs(stage[3]), 1e-300))


@njit(inline="always", **_OPTIONS)
def tracking_rate(omega):
    """A tracking root's rate for its sub-step plan: |ω| (0 for NaN). Not |ξ̇/ξ|: ξ of
    dynamic feedback starting at or crossing 0 grows as ξ̇·t, so |ξ̇/ξ| ≈ 1/t at a sub-step's
    first stage, ≈ 1/h whatever h, and no plan would meet it; ω, guarded by ξ_min, carries
    the 1/ξ growth that matters."""
    return max(0.0, abs(omega))   # (numba's max(a, b) is b if b > a else a: NaN gives 0.0)


@njit(inline="always", **_OPTIONS)
def wide_substep(substeps, k, n_steps, dt):
    """dt over the fewest sub-steps of output step k and of its neighbours, leaving out those
    at ``MAX_SUBSTEPS`` or more (0 if all are). A tracking root's rate met in step k asks for
    sub-steps in steps k − 1, k and k + 1, never more than ``MAX_SUBSTEPS`` (the simulator's
    ``measured_plan``), so the largest ``tracking_rate`` × this over a copy's run (its
    statistic ``STEP_RATE``) is within the plan's factor exactly (to rounding) when the plan
    gives the copy every sub-step its own rates ask for: the simulator runs again only the
    copies of a batch that are short."""
    m = MAX_SUBSTEPS
    if substeps[k] < m:
        m = substeps[k]
    if k > 0 and substeps[k - 1] < m:
        m = substeps[k - 1]
    if k + 1 < n_steps and substeps[k + 1] < m:
        m = substeps[k + 1]
    return dt / m if m < MAX_SUBSTEPS else 0.0


@njit(inline="always", **_OPTIONS)
def largest_rate(k, n):
    """The largest of the first n rates in row ``RATE_ROW`` of a stage's rates ``k`` (k1, k2 or
    k3; not negative and not NaN: ``tracking_rate``, or ``stage_rate`` under max(0, ·)): a
    maximum of their bit patterns as integers, which order non-negative floats as their
    values do and which LLVM vectorizes; a float maximum carried from copy to copy it may not
    reorder (NaN), and the loop holding it ran 2.5x slower. The largest is written back to the row's first slot and
    read there as the float it is."""
    bits = k[RATE_ROW].view(np.int64)
    largest = bits[0]
    for i in range(1, n):
        largest = max(largest, bits[i])
    bits[0] = largest
    return k[RATE_ROW, 0]


@njit(inline="always", **_OPTIONS)
def robot_stats(stats, r, b):
    """A robot's running statistics, rows 0 … ``ROBOT_STATS`` − 1 (E_MEAN … SAT_ANY), as
    a tuple (the rows after them are kept for formations only)."""
    return (stats[0, r, b], stats[1, r, b], stats[2, r, b], stats[3, r, b], stats[4, r, b], stats[5, r, b],
            stats[6, r, b], stats[7, r, b], stats[8, r, b], stats[9, r, b], stats[10, r, b], stats[11, r, b],
            stats[12, r, b], stats[13, r, b], stats[14, r, b], stats[15, r, b], stats[16, r, b], stats[17, r, b],
            stats[18, r, b], stats[19, r, b])


def add_sample(old, t, k, v, omega, singular, sat_v, sat_w, err1, err2):
    """The running statistics ``old`` (``robot_stats``) with the sample of output step k
    (time t) added: its errors, and the command in force (v, ω and its event flags)."""
    (e_mean, e_m2, e_sq, e_max, _, h_sum, h_sq, h_max, _, v_peak, v_peak_t, w_peak, w_peak_t, v_sq, w_sq, sat_v_sum,
     sat_w_sum, singular_sum, first_singular, sat_any_sum) = old
    e = abs(err1)
    delta = e - e_mean
    mean = e_mean + delta * (1.0 / (k + 1.0))   # (the reciprocal is one per step, outside a batch's loop)
    heading = abs(err2)
    speed, turn = abs(v), abs(omega)
    return (mean, e_m2 + delta * (e - mean), e_sq + e * e, max(e_max, e), e, h_sum + heading, h_sq + heading * heading,
            max(h_max, heading), heading, max(v_peak, speed), t if speed > v_peak else v_peak_t, max(w_peak, turn),
            t if turn > w_peak else w_peak_t, v_sq + v * v, w_sq + omega * omega, sat_v_sum + sat_v,
            sat_w_sum + sat_w, singular_sum + singular, min(first_singular, t if singular > 0.0 else np.inf),
            sat_any_sum + max(sat_v, sat_w))


# Compiled once per process as functions of their own (LLVM inlines them into the kernels),
# not copied into every kernel by numba: one variant per kernel kind, as ``root_command``.
add_sample_exact = njit(error_model="numpy", fastmath=False)(add_sample)
add_sample = njit(error_model="numpy", fastmath={"contract"})(add_sample)
add_sample_exact._set_uuid(f"{__name__}.add_sample_exact")
add_sample._set_uuid(f"{__name__}.add_sample")


@njit(inline="always", **_OPTIONS)
def store_stats(stats, r, b, values):
    """Write a robot's running statistics (``robot_stats``, ``add_sample``) back."""
    (stats[0, r, b], stats[1, r, b], stats[2, r, b], stats[3, r, b], stats[4, r, b], stats[5, r, b], stats[6, r, b],
     stats[7, r, b], stats[8, r, b], stats[9, r, b], stats[10, r, b], stats[11, r, b], stats[12, r, b],
     stats[13, r, b], stats[14, r, b], stats[15, r, b], stats[16, r, b], stats[17, r, b], stats[18, r, b],
     stats[19, r, b]) = values


@njit(inline="always", **_OPTIONS)
def store_record(record, k, r, b, row):
    """Write one sample of a robot's record rows (``record_row``)."""
    (record[0, k, r, b], record[1, k, r, b], record[2, k, r, b], record[3, k, r, b], record[4, k, r, b],
     record[5, k, r, b], record[6, k, r, b], record[7, k, r, b], record[8, k, r, b], record[9, k, r, b]) = row


@njit(inline="always", **_OPTIONS)
def record_row(x, y, theta, xi, v, omega, err1, err2, singular, sat_v, sat_w):
    """One sample of a robot's record rows, REC_X … REC_SATURATED."""
    return (x, y, theta, xi, v, omega, err1, err2, singular, sat_v + 2.0 * sat_w)


@njit(inline="always", **_OPTIONS)
def store_link_record(record, k, r, b, out1, out2, rate1, rate2, sin_gamma):
    """Write one sample of a follower's link rows, REC_OUT1 … REC_SIN_GAMMA (zeros for a root)."""
    (record[10, k, r, b], record[11, k, r, b], record[12, k, r, b], record[13, k, r, b],
     record[14, k, r, b]) = out1, out2, rate1, rate2, sin_gamma


@njit(inline="always", **_OPTIONS)
def idle_law(x, y, theta, cos_theta, sin_theta, xi, ref, gains):
    """The placeholder second law of a one-law kernel (never selected)."""
    return 0.0, 0.0, 0.0, 0.0


IdleFields = namedtuple("IdleFields", ("unused",))


@njit(error_model="numpy", fastmath=False)
def goal_errors(gx, gy, gtheta, x, y, theta):
    """(position error norm, signed heading error) of a pose against (gx, gy, gθ). Compiled
    on its own without FMA contraction (LLVM inlines it), so that every kernel computes the
    same norm whatever the code around it."""
    ex, ey = gx - x, gy - y
    return math.sqrt(ex * ex + ey * ey), wrap_angle(gtheta - theta)


@njit(inline="always", **_OPTIONS)
def root_errors(posture, fields, r, b, x, y, theta, ref):
    """(position error norm, signed heading error) against the reference or the goal."""
    if posture:
        return goal_errors(fields[0, r, b], fields[1, r, b], fields[2, r, b], x, y, theta)
    return goal_errors(ref[REF_X], ref[REF_Y], ref[REF_THETA], x, y, theta)


@njit(**_OPTIONS)   # (one for every law, two compiled: tracking and posture; LLVM inlines it. Per law it cost 1-2 s)
def add_samples(sample, r, c0, c1, ref, k, posture, measuring, fields, stats, record, record_at, step_rate):
    """Add the samples ``keep_sample`` kept at output step k to the statistics and record of
    ``Kernel.roots`` (copy b of robot r at ``record``'s robot and copy ``record_at`` + (r, b));
    with ``measuring``, |ω| to ``step_rate``."""
    t = ref[0]
    for b in range(c0, c1):
        i = b - c0
        err1, err2 = root_errors(posture, fields, r, b, sample[0, i], sample[1, i], sample[2, i], ref)
        store_stats(stats, r, b, add_sample(robot_stats(stats, r, b), t, k, sample[4, i], sample[5, i], sample[6, i],
                                            sample[7, i], sample[8, i], err1, err2))
    if record.shape[1] != 0:   # a loop of its own, as in ``accumulate``
        for b in range(c0, c1):
            i = b - c0
            err1, err2 = root_errors(posture, fields, r, b, sample[0, i], sample[1, i], sample[2, i], ref)
            store_record(record, k, record_at[0] + r, record_at[1] + b,
                         record_row(sample[0, i], sample[1, i], sample[2, i], sample[3, i], sample[4, i],
                                    sample[5, i], err1, err2, sample[6, i], sample[7, i], sample[8, i]))
    if measuring:
        for i in range(c1 - c0):
            step_rate[k] = max(step_rate[k], abs(sample[5, i]))


@njit(**_OPTIONS)
def run_alone(root, r, b, state, fields, limits, rows, row_start, substeps, dt, xi_speed, k_start, k_stop, n_steps,
              stats, record, step_rate, given):
    """``integrate`` of lone root r of copy b under continuous-time control, its state and
    statistics in registers from k_start to k_stop: for a few copies, the loops over the
    batch (with LLVM's run-time overlap checks at each entry) cost more than they do. With
    ``given`` states (N+1, 4, R, B), not empty, it scores them instead (sub-steps 0).

    ``root`` is ``(address, posture, measuring)``: the law's entry
    (``nonholo.sim.lawcall.law_entry``), 1 for a posture law, and which rates go to
    ``step_rate``: ``MEASURE_STAGES`` every stage's (a posture law's start-up is not known in
    advance), ``MEASURE_FIRST_STAGE`` each sub-step's first stage's ``tracking_rate`` (a
    tracking law's transients: far starts, ξ near 0; as ``roots`` measures them). The law is called
    through its address, so this function is compiled once for every law (a single run pays
    a few nanoseconds per law evaluation for it: about 5 % of its time)."""
    address, posture, measuring = root
    recording = record.shape[1] != 0
    scoring = given.shape[0] != 0
    gains_i = (address, stack_copy(field_row(fields, r, b)))
    x, y, theta, xi = state[0, r, b], state[1, r, b], state[2, r, b], state[3, r, b]
    v_max, omega_max = limits[0, r, b], limits[1, r, b]
    sample = robot_stats(stats, r, b)
    own = stats[STEP_RATE, r, b]
    for k in range(k_start, k_stop + (1 if k_stop == n_steps else 0)):
        if scoring:
            x, y, theta, xi = given[k, 0, r, b], given[k, 1, r, b], given[k, 2, r, b], given[k, 3, r, b]
        row = row_start[k]
        ref = row_values(rows, row)
        x0, y0, theta0, xi0 = x, y, theta, xi
        if scoring or k == n_steps:   # no step follows: the law alone
            v, omega, _, singular, sat_v, sat_w, _, _ = root_command(law_at_address, gains_i, x, y, theta, xi,
                                                                     row_address(rows, row), v_max, omega_max)
        else:   # the first RK4 stage's command is the one in force at t_k (as in ``roots``)
            v = omega = singular = sat_v = sat_w = 0.0
            m = substeps[k]
            wide = wide_substep(substeps, k, n_steps, dt)
            for j in range(m):
                new, s1, s2, s3, s4 = root_rk4_fused(law_at_address, gains_i, x, y, theta, xi,
                                                     row_address(rows, row + 2 * j),
                                                     row_address(rows, row + 2 * j + 1),
                                                     row_address(rows, row + 2 * j + 2), dt / m, v_max, omega_max)
                if j == 0:
                    v, omega, singular, sat_v, sat_w = s1[5], s1[6], s1[7], s1[8], s1[9]
                x, y, theta, xi = new
                if measuring == MEASURE_STAGES:
                    step_rate[k] = max(step_rate[k], stage_rate(s1, xi_speed), stage_rate(s2, xi_speed),
                                       stage_rate(s3, xi_speed), stage_rate(s4, xi_speed))
                elif measuring == MEASURE_FIRST_STAGE:
                    rate = tracking_rate(s1[6])
                    step_rate[k] = max(step_rate[k], rate)
                    own = max(own, rate * wide)
        err1, err2 = root_errors(posture != 0, fields, r, b, x0, y0, theta0, ref)
        sample = add_sample(sample, ref[0], k, v, omega, singular, sat_v, sat_w, err1, err2)
        if recording:
            store_record(record, k, r, b, record_row(x0, y0, theta0, xi0, v, omega, err1, err2, singular, sat_v, sat_w))
        if measuring == MEASURE_STAGES:
            step_rate[k] = max(step_rate[k], abs(omega))
    state[0, r, b], state[1, r, b], state[2, r, b], state[3, r, b] = x, y, theta, xi
    store_stats(stats, r, b, sample)
    stats[STEP_RATE, r, b] = own


@njit(**_OPTIONS)
def integrate_alone(root, state, fields, limits, rows, row_start, substeps, targets, offsets, kinds, order, parents,
                    feeds, branch, sin_floor, d_max, xi_speed, dt, hold_every, k_start, k_stop, n_steps, stats,
                    pair_stats, record, held, step_rate, held_given):
    """``integrate`` (same arguments after ``root``) for lone roots under continuous-time
    control, one robot at a time (``run_alone``): the faster for a few copies
    (``ALONE_BELOW``). ``root`` (2,) int64: the law's (entry address, posture) (``LoneRoot``
    binds it); its turn rates are measured (``run_alone``)."""
    no_states = np.empty((0, 4, state.shape[1], state.shape[2]))
    law = (root[0], root[1], MEASURE_STAGES if root[1] else MEASURE_FIRST_STAGE)
    for r in range(state.shape[1]):
        for b in range(state.shape[2]):
            run_alone(law, r, b, state, fields, limits, rows, row_start, substeps, dt, xi_speed, k_start, k_stop,
                      n_steps, stats, record, step_rate, no_states)


@njit(**_OPTIONS)
def score_alone(root, states, fields, limits, rows, targets, offsets, kinds, order, parents, branch, sin_floor, d_max,
                stats, pair_stats, record, hold_every, helds):
    """``score`` (same arguments after ``root``, see ``integrate_alone``) for lone roots
    under continuous-time control (``hold_every`` 0): ``run_alone`` over the given states,
    with no sub-steps."""
    n_steps = states.shape[0] - 1
    state = states[0].copy()
    row_start, substeps, step_rate = np.arange(n_steps + 1), np.zeros(max(n_steps, 1), np.int64), np.zeros(n_steps + 1)
    k_start = np.int64(0)   # not a literal 0, which would compile ``run_alone`` a second time
    law = (root[0], root[1], np.int64(MEASURE_NONE))   # (an int64 as in ``integrate_alone``: one compilation)
    for r in range(state.shape[1]):
        for b in range(state.shape[2]):
            run_alone(law, r, b, state, fields, limits, rows, row_start, substeps, 0.0, 0.0, k_start, n_steps,
                      n_steps, stats, record, step_rate, states)


class LoneRoot:
    """``integrate_alone`` or ``score_alone`` bound to the law of a kernel of lone roots:
    ``law`` is (law, gain class, posture). Its entry (``nonholo.sim.lawcall.law_entry``) is
    made on the first call, so runs that never use this function never compile it."""

    def __init__(self, function, law):
        self.function, self.law, self.root = function, law, None

    def __call__(self, *args):
        if self.root is None:   # set only once made: a law that fails to compile leaves None
            law, gains, posture = self.law
            self.root = np.array([law_entry(law, gains).address, posture], dtype=np.int64)
        rows = np.ascontiguousarray(args[3], dtype=np.float64)   # the law reads reference rows by address
        if rows.ndim != 2 or rows.shape[1] != REF_SIZE:
            raise ValueError(f"reference rows must be (rows, {REF_SIZE}), got {rows.shape}")
        return self.function(self.root, *args[:3], rows, *args[4:])


class Kernel(namedtuple("Kernel", ("integrate", "evaluate", "score", "alone", "score_alone", "roots"))):
    """The compiled functions of one kernel (``make_kernel``); ``alone``, ``score_alone`` and
    ``roots`` are None for graphs with followers. numba compiles each on its first call: a
    run pays only for the functions it uses."""

    def integrator(self, sampled_data: bool, copies: int):
        """The time loop for ``copies`` copies of this kernel's graph: ``alone`` for a few
        copies of lone roots under continuous-time control, ``roots`` for more, else
        ``integrate`` (graphs with followers, sampled-data control); all take
        ``integrate``'s arguments."""
        if self.roots is None or sampled_data:
            return self.integrate
        return self.alone if copies < ALONE_BELOW else self.roots

    def scorer(self, sampled_data: bool):
        """The function that scores trajectories computed elsewhere: ``score_alone`` for
        lone roots under continuous-time control (``alone``'s own code, compiled for single
        runs anyway), else ``score``."""
        return self.score if self.score_alone is None or sampled_data else self.score_alone


def make_kernel(law_a, gains_a, law_b, gains_b, followers: bool) -> Kernel:
    """Compile (once, cached on disk) the functions that simulate a robot graph whose roots
    run ``law_a`` or ``law_b`` (namedtuple classes ``gains_a``, ``gains_b`` of their fields)
    and which has followers if ``followers`` (a compile-time choice: graphs of lone roots
    compile no formation code). A kernel without followers runs one law (``law_b`` is
    ``idle_law``): each lone root is a graph of its own, grouped with those of its law.

    Returns a ``Kernel`` (integrate, evaluate, score, alone):

    * ``integrate(state, fields, limits, rows, row_start, substeps, targets, offsets, kinds,
      order, parents, feeds, branch, sin_floor, d_max, xi_speed, dt, hold_every, k_start,
      k_stop, n_steps, stats, pair_stats, record, held, step_rate, held_given)``: the time loop
      of graphs with followers, and of sampled-data control (a kernel of lone roots leaves
      continuous-time control to ``roots`` and ``alone``: ``Kernel.integrator`` picks);
      with ``held_given`` a control instant keeps the commands already in ``held`` (the caller
      sets them, running one control period per call: the link step, ``nonholo.sim.linkstep``);
    * ``evaluate(state, fields, limits, ref_row, targets, target_row, offsets, kinds, order,
      parents, branch, sin_floor, instant)``: every robot's command and outputs at one
      instant, parents first (scipy's right-hand side reads v, ω, ξ̇ from ``instant``; a kernel
      without followers leaves the link rows I_OUT1 … I_SIN_GAMMA as they are: pass zeros);
    * ``score(states, fields, limits, rows, targets, offsets, kinds, order, parents, branch,
      sin_floor, d_max, stats, pair_stats, record, hold_every, helds)``: statistics and record
      of a trajectory computed elsewhere (the scipy cross-check, or the robots of a fleet run:
      states (N+1, 4, R, B), and with ``hold_every`` > 0 the commands each robot held,
      helds (N+1, HELD_COUNT, R, B)), by the same code;
    * ``roots``: ``integrate`` (same arguments) for lone roots under continuous-time control,
      ``ROOTS_CHUNK`` copies at a time through the whole time loop, each sample taken from the
      first stage of the RK4 step that starts at it (no fifth law evaluation); a call whose
      copies have no limits (all inf) runs a time loop without the clipping (the same
      numbers); None for graphs with followers;
    * ``alone``: ``integrate`` for lone roots under continuous-time control one robot at a
      time, state and statistics in registers (fewer than ``ALONE_BELOW`` copies): the
      module's ``integrate_alone``, the same compiled code for every law (``LoneRoot``
      binds the law's entry); None for graphs with followers;
    * ``score_alone``: ``score`` (same arguments) for lone roots under continuous-time
      control, one robot at a time through ``alone``'s code; None for graphs with followers
      (``Kernel.scorer`` picks).

    Only these closures capture the laws: numba caches closures over module-level
    functions across processes, not closures over other closures.
    """
    if law_b is not idle_law and not followers:   # (simulate groups lone roots by law)
        raise ValueError("a kernel of lone roots runs one law: two laws need a graph with followers")
    stable_cache_identity(law_a)
    stable_cache_identity(law_b)
    # Graphs with followers keep every operation as written (no FMA contraction): their cost
    # is the graph, not the arithmetic, and nearly singular l–l passages are sensitive to it.
    _OPTIONS = dict(cache=True, error_model="numpy", fastmath={"contract"} if not followers else False)
    n_a, n_b = len(gains_a._fields), len(gains_b._fields)
    posture_a = gains_a._fields[:3] == GOAL_FIELDS
    posture_b = gains_b._fields[:3] == GOAL_FIELDS
    # Turn rates not known in advance are measured: at every stage for followers and posture
    # laws' start-up, at each sub-step's first stage for a tracking law's transients (far
    # starts, ξ near 0) in ``roots``, its statistics loop (see ``run_alone``).
    measuring = followers or posture_a or posture_b
    two_laws = law_b is not idle_law  # one-law kernels compile no law dispatch in their loops
    root_rk4 = root_rk4_exact if followers else root_rk4_fused
    command = root_command_exact if followers else root_command
    add_sample_ = add_sample_exact if followers else add_sample
    # Per-step functions: inlined by numba in lone-root kernels (a single run's speed is their
    # call overhead); compiled once each in kernels with followers, whose per-step work dwarfs
    # a call and whose inlined copies made up most of their compile time.
    inline = "never" if followers else "always"

    @njit(inline=inline, **_OPTIONS)
    def evaluate_at(state, fields, limits, ref, targets, target_row, offsets, kinds, order, parents, branch, sin_floor,
                    instant):
        for position in range(order.size):
            r = order[position]
            kind = kinds[r]
            p1, p2 = parents[0, r], parents[1, r]
            for b in range(state.shape[2]):
                x, y, theta, xi = state[0, r, b], state[1, r, b], state[2, r, b], state[3, r, b]
                v_max, omega_max = limits[0, r, b], limits[1, r, b]
                out1 = out2 = rate1 = rate2 = sin_gamma = singular = xi_dot = 0.0
                if kind == ROOT_A or kind == ROOT_B:
                    if not (two_laws and kind == ROOT_B):
                        v, omega, xi_dot, singular, sat_v, sat_w, _, _ = command(
                            law_a, gains_a(*field_row(fields, r, b)[:n_a]), x, y, theta, xi, ref, v_max, omega_max)
                        err1, err2 = root_errors(posture_a, fields, r, b, x, y, theta, ref)
                    else:
                        v, omega, xi_dot, singular, sat_v, sat_w, _, _ = command(
                            law_b, gains_b(*field_row(fields, r, b)[:n_b]), x, y, theta, xi, ref, v_max, omega_max)
                        err1, err2 = root_errors(posture_b, fields, r, b, x, y, theta, ref)
                elif followers:
                    target_row = target_row if targets.shape[0] > 1 else 0   # one row: constant targets
                    z1_d = targets[target_row, 0, r] + offsets[0, r, b]
                    z2_d = targets[target_row, 1, r] + offsets[1, r, b]
                    if kind == SEPARATION_BEARING:
                        v, omega, sat_v, sat_w, _, _, out1, out2, rate1, rate2 = bearing_command(
                            x, y, theta, state[0, p1, b], state[1, p1, b], state[2, p1, b], instant[I_V, p1, b],
                            instant[I_OMEGA, p1, b], branch[r, b], z1_d, z2_d, targets[target_row, 2, r],
                            targets[target_row, 3, r], fields[K1, r, b], fields[K2, r, b], fields[OFFSET_D, r, b],
                            v_max, omega_max)
                    else:
                        v, omega, sat_v, sat_w, singular, _, _, out1, out2, rate1, rate2, sin_gamma = pair_command(
                            x, y, theta, state[0, p1, b], state[1, p1, b], state[2, p1, b], instant[I_V, p1, b],
                            state[0, p2, b], state[1, p2, b], state[2, p2, b], instant[I_V, p2, b], z1_d, z2_d,
                            targets[target_row, 2, r], targets[target_row, 3, r], fields[K1, r, b], fields[K2, r, b],
                            fields[OFFSET_D, r, b], sin_floor, v_max, omega_max)
                    err1, err2 = z1_d - out1, z2_d - out2   # desired minus actual (spec README)
                else:
                    v = omega = sat_v = sat_w = err1 = err2 = 0.0
                instant[I_V, r, b], instant[I_OMEGA, r, b], instant[I_XI_DOT, r, b] = v, omega, xi_dot
                instant[I_SINGULAR, r, b], instant[I_SAT_V, r, b], instant[I_SAT_OMEGA, r, b] = singular, sat_v, sat_w
                instant[I_ERR1, r, b], instant[I_ERR2, r, b] = err1, err2
                if followers:   # links' outputs; in a kernel of lone roots these rows keep their zeros
                    instant[I_OUT1, r, b], instant[I_OUT2, r, b] = out1, out2
                    instant[I_RATE1, r, b], instant[I_RATE2, r, b], instant[I_SIN_GAMMA, r, b] = rate1, rate2, sin_gamma

    @njit(**_OPTIONS)
    def evaluate(state, fields, limits, ref, targets, target_row, offsets, kinds, order, parents, branch, sin_floor,
                 instant):
        evaluate_at(state, fields, limits, ref, targets, target_row, offsets, kinds, order, parents, branch, sin_floor,
                    instant)

    @njit(inline="always", **_OPTIONS)
    def accumulate(state, instant, t, k, kinds, fields, d_max, stats, pair_stats, record, recording):
        """Add every robot's sample at output step k (time t) to its statistics and record:
        its errors and outputs at the state, the command in force (``instant``)."""
        n_robots, n_batch = state.shape[1], state.shape[2]
        for r in range(n_robots):
            for b in range(n_batch):
                new = add_sample_(robot_stats(stats, r, b), t, k, instant[I_V, r, b], instant[I_OMEGA, r, b],
                                 instant[I_SINGULAR, r, b], instant[I_SAT_V, r, b], instant[I_SAT_OMEGA, r, b],
                                 instant[I_ERR1, r, b], instant[I_ERR2, r, b])
                store_stats(stats, r, b, new)
        if recording:   # a loop of its own: the statistics loop stays small enough to vectorize cheaply
            for r in range(n_robots):
                for b in range(n_batch):
                    row = record_row(state[0, r, b], state[1, r, b], state[2, r, b], state[3, r, b],
                                     instant[I_V, r, b], instant[I_OMEGA, r, b], instant[I_ERR1, r, b],
                                     instant[I_ERR2, r, b], instant[I_SINGULAR, r, b], instant[I_SAT_V, r, b],
                                     instant[I_SAT_OMEGA, r, b])
                    store_record(record, k, r, b, row)
                    if followers:   # (a graph without followers records no link rows)
                        store_link_record(record, k, r, b, instant[I_OUT1, r, b], instant[I_OUT2, r, b],
                                          instant[I_RATE1, r, b], instant[I_RATE2, r, b], instant[I_SIN_GAMMA, r, b])
        if followers:
            for r in range(n_robots):
                if kinds[r] == SEPARATION_SEPARATION:
                    for b in range(n_batch):
                        signed = instant[I_SIN_GAMMA, r, b]
                        s = abs(signed)
                        stats[MIN_SIN_T, r, b] = t if s < stats[MIN_SIN, r, b] else stats[MIN_SIN_T, r, b]
                        stats[MIN_SIN, r, b] = min(stats[MIN_SIN, r, b], s)
                        # a sign change from the last non-zero sample: sin(γ1 − γ2) went through 0,
                        # the singular configuration, since then (spec §3.2)
                        stats[SIN_CROSSINGS, r, b] += 1.0 if signed * stats[SIN_LAST, r, b] < 0.0 else 0.0
                        stats[SIN_LAST, r, b] = signed if signed != 0.0 else stats[SIN_LAST, r, b]
            if n_robots > 1:
                for b in range(n_batch):
                    closest, first, second = np.inf, -1, -1
                    for r in range(n_robots):
                        near, who = np.inf, -1
                        for q in range(n_robots):
                            if q != r:
                                dx, dy = state[0, q, b] - state[0, r, b], state[1, q, b] - state[1, r, b]
                                distance = math.sqrt(dx * dx + dy * dy)
                                if distance < near:
                                    near, who = distance, q
                        if near < stats[NEAR, r, b]:
                            stats[NEAR, r, b], stats[NEAR_T, r, b], stats[NEAR_WHO, r, b] = near, t, who
                        if kinds[r] >= SEPARATION_BEARING and near < 2.0 * fields[OFFSET_D, r, b]:
                            stats[BELOW_2D, r, b] += 1.0
                        if near < closest:
                            closest, first, second = near, min(r, who), max(r, who)
                    if closest < pair_stats[CLOSEST, b]:
                        pair_stats[CLOSEST, b], pair_stats[CLOSEST_T, b] = closest, t
                        pair_stats[CLOSEST_I, b], pair_stats[CLOSEST_J, b] = first, second
                    if closest < 2.0 * d_max[b]:
                        pair_stats[BELOW_ANY, b] += 1.0

    @njit(**_OPTIONS)
    def follower_stage(kind, x, y, theta, parent_1, parent_2, branch, target, k1, k2, d, sin_floor, v_max, omega_max):
        """(ẋ, ẏ, θ̇, v, ω) of a follower at one RK4 stage; ``parent_i`` = (x, y, θ, v, ω) of
        its parents at that stage, ``target`` = (z1_d, z2_d, ż1_d, ż2_d)."""
        if kind == SEPARATION_BEARING:
            v, omega, _, _, cos_t, sin_t, _, _, _, _ = bearing_command(
                x, y, theta, parent_1[0], parent_1[1], parent_1[2], parent_1[3], parent_1[4], branch, target[0],
                target[1], target[2], target[3], k1, k2, d, v_max, omega_max)
        else:
            v, omega, _, _, _, cos_t, sin_t, _, _, _, _, _ = pair_command(
                x, y, theta, parent_1[0], parent_1[1], parent_1[2], parent_1[3], parent_2[0], parent_2[1],
                parent_2[2], parent_2[3], target[0], target[1], target[2], target[3], k1, k2, d, sin_floor, v_max,
                omega_max)
        dx, dy, dtheta = unicycle_rates(v, omega, cos_t, sin_t)
        return dx, dy, dtheta, v, omega

    @njit(inline=inline, **_OPTIONS)
    def substep(state, fields, limits, rows, row, h, targets, offsets, kinds, order, parents, feeds, branch,
                sin_floor, xi_speed, sampled_data, held, stage_pose, stage_command):
        """One classical RK4 sub-step of every robot (parents first); returns the fastest
        rate met (only measured for graphs with followers)."""
        r0, r1, r2 = row_values(rows, row), row_values(rows, row + 1), row_values(rows, row + 2)
        half, sixth = 0.5 * h, h / 6.0
        peak = 0.0
        n_batch = state.shape[2]
        for position in range(order.size):
            r = order[position]
            kind = kinds[r]
            if sampled_data:
                for b in range(n_batch):
                    omega = held[HELD_OMEGA, r, b]
                    state[0, r, b], state[1, r, b], state[2, r, b], state[3, r, b] = unicycle_step(
                        state[0, r, b], state[1, r, b], state[2, r, b], state[3, r, b], held[HELD_V, r, b], omega,
                        held[HELD_XI_DOT, r, b], h)
                    if measuring:
                        peak = max(peak, abs(omega))
            elif followers and (kind == ROOT_A or kind == ROOT_B):   # (lone roots: ``roots``)
                feeding = feeds[r] != 0
                for b in range(n_batch):
                    if not (two_laws and kind == ROOT_B):
                        new, s1, s2, s3, s4 = root_rk4(
                            law_a, gains_a(*field_row(fields, r, b)[:n_a]), state[0, r, b], state[1, r, b],
                            state[2, r, b], state[3, r, b], r0, r1, r2, h, limits[0, r, b], limits[1, r, b])
                    else:
                        new, s1, s2, s3, s4 = root_rk4(
                            law_b, gains_b(*field_row(fields, r, b)[:n_b]), state[0, r, b], state[1, r, b],
                            state[2, r, b], state[3, r, b], r0, r1, r2, h, limits[0, r, b], limits[1, r, b])
                    state[0, r, b], state[1, r, b], state[2, r, b], state[3, r, b] = new
                    if measuring:
                        peak = max(peak, stage_rate(s1, xi_speed), stage_rate(s2, xi_speed), stage_rate(s3, xi_speed),
                                   stage_rate(s4, xi_speed))
                    if feeding:
                        store_stages(stage_pose, stage_command, r, b, (s1[0], s1[1], s1[2], s1[5], s1[6]),
                                     (s2[0], s2[1], s2[2], s2[5], s2[6]), (s3[0], s3[1], s3[2], s3[5], s3[6]),
                                     (s4[0], s4[1], s4[2], s4[5], s4[6]))
            elif followers:
                # Followers are few and their laws long: their four stages run as a loop (not
                # unrolled), which keeps the compiled code small.
                feeding = feeds[r] != 0
                p1, p2 = parents[0, r], parents[1, r]
                for b in range(n_batch):
                    x, y, theta = state[0, r, b], state[1, r, b], state[2, r, b]
                    v_max, omega_max = limits[0, r, b], limits[1, r, b]
                    k1, k2, d = fields[K1, r, b], fields[K2, r, b], fields[OFFSET_D, r, b]
                    o1, o2, bearing = offsets[0, r, b], offsets[1, r, b], branch[r, b]
                    dx = dy = dtheta = 0.0
                    first_x = first_y = first_theta = mid_x = mid_y = mid_theta = 0.0
                    for s in range(4):
                        weight = 0.0 if s == 0 else (half if s < 3 else h)
                        sx, sy, st = x + weight * dx, y + weight * dy, theta + weight * dtheta
                        tr = row + (s + 1) // 2 if targets.shape[0] > 1 else 0   # one row: constant targets
                        # the first stage takes the targets just after its time: a step at the
                        # sub-step's start is integrated on its new target throughout
                        tc = 4 if s == 0 else 0
                        target = (targets[tr, tc, r] + o1, targets[tr, tc + 1, r] + o2, targets[tr, 2, r],
                                  targets[tr, 3, r])
                        dx, dy, dtheta, v, omega = follower_stage(
                            kind, sx, sy, st, parent_stage(stage_pose, stage_command, s, p1, b),
                            parent_stage(stage_pose, stage_command, s, p2, b), bearing, target, k1, k2, d, sin_floor,
                            v_max, omega_max)
                        if s == 0:
                            first_x, first_y, first_theta = dx, dy, dtheta
                        elif s == 1:
                            mid_x, mid_y, mid_theta = dx, dy, dtheta
                        elif s == 2:
                            mid_x, mid_y, mid_theta = mid_x + dx, mid_y + dy, mid_theta + dtheta
                        peak = max(peak, abs(omega))
                        if feeding:
                            stage_pose[s, 0, r, b], stage_pose[s, 1, r, b], stage_pose[s, 2, r, b] = sx, sy, st
                            stage_command[s, 0, r, b], stage_command[s, 1, r, b] = v, omega
                    state[0, r, b] = x + sixth * (first_x + 2.0 * mid_x + dx)
                    state[1, r, b] = y + sixth * (first_y + 2.0 * mid_y + dy)
                    state[2, r, b] = theta + sixth * (first_theta + 2.0 * mid_theta + dtheta)
        if followers and not sampled_data:
            update_branches(state, fields, kinds, parents, branch)
        return peak

    @njit(inline="always", **_OPTIONS)
    def update_branches(state, fields, kinds, parents, branch):
        """Move every l–φ bearing branch to the bearing at the current state."""
        for r in range(kinds.size):
            if kinds[r] != SEPARATION_BEARING:
                continue
            p = parents[0, r]
            for b in range(state.shape[2]):
                theta = state[2, r, b]
                sin_t, cos_t = sincos(theta)
                _, raw, _, _, _, _ = link_geometry(state[0, p, b], state[1, p, b], state[2, p, b], state[0, r, b],
                                                  state[1, r, b], cos_t, sin_t, theta, fields[OFFSET_D, r, b])
                branch[r, b] = continuous_bearing(raw, branch[r, b])

    @njit(**_OPTIONS)
    def integrate(state, fields, limits, rows, row_start, substeps, targets, offsets, kinds, order, parents, feeds,
                  branch, sin_floor, d_max, xi_speed, dt, hold_every, k_start, k_stop, n_steps, stats, pair_stats,
                  record, held, step_rate, held_given):
        sampled_data = hold_every != 0
        if not followers and not sampled_data:   # not compiled here: ``Kernel.integrator`` picks
            raise ValueError("lone roots under continuous-time control run in Kernel.roots or Kernel.alone")
        recording = record.shape[1] != 0
        n_robots, n_batch = state.shape[1], state.shape[2]
        instant = np.zeros((INSTANT_COUNT, n_robots, n_batch))
        scratch = n_robots if followers else 0
        stage_pose = np.zeros((4, 3, scratch, n_batch))
        stage_command = np.zeros((4, 2, scratch, n_batch))
        for k in range(k_start, k_stop + (1 if k_stop == n_steps else 0)):
            row = row_start[k]
            ref = row_values(rows, row)
            if followers and sampled_data and k % hold_every == 0:
                # Sampled data: bearings move to their branch at control instants only, as
                # a robot that sees its parent's pose only then does (spec fleet.md §6).
                update_branches(state, fields, kinds, parents, branch)
            evaluate_at(state, fields, limits, ref, targets, row, offsets, kinds, order, parents, branch, sin_floor,
                        instant)
            if sampled_data:   # a control instant holds the new commands; between them they stay in force
                # (``held_given``: the caller set them at this instant, e.g. the link step)
                refresh = k % hold_every == 0 and not held_given
                for r in range(n_robots):
                    for b in range(n_batch):
                        for field in range(HELD_COUNT):
                            if refresh:
                                held[field, r, b] = instant[field, r, b]
                            else:
                                instant[field, r, b] = held[field, r, b]
            accumulate(state, instant, ref[0], k, kinds, fields, d_max, stats, pair_stats, record, recording)
            if k == n_steps:
                break
            m = substeps[k]
            for j in range(m):
                rate = substep(state, fields, limits, rows, row + 2 * j, dt / m, targets, offsets, kinds, order, parents,
                               feeds, branch, sin_floor, xi_speed, sampled_data, held, stage_pose, stage_command)
                if measuring:
                    step_rate[k] = max(step_rate[k], rate)
            if measuring:
                for r in range(n_robots):
                    for b in range(n_batch):
                        step_rate[k] = max(step_rate[k], abs(instant[I_OMEGA, r, b]))

    @njit(**_OPTIONS)
    def score(states, fields, limits, rows, targets, offsets, kinds, order, parents, branch, sin_floor, d_max, stats,
              pair_stats, record, hold_every, helds):
        n_robots, n_batch = states.shape[2], states.shape[3]
        instant = np.zeros((INSTANT_COUNT, n_robots, n_batch))
        sampled_data = hold_every != 0
        recording = record.shape[1] != 0
        for k in range(states.shape[0]):
            state = states[k]
            if followers and (not sampled_data or k % hold_every == 0):
                update_branches(state, fields, kinds, parents, branch)
            ref = row_values(rows, k)
            evaluate_at(state, fields, limits, ref, targets, k, offsets, kinds, order, parents, branch, sin_floor,
                        instant)
            if sampled_data:   # the commands each robot held stand for the instant's commands
                for field in range(HELD_COUNT):
                    for r in range(n_robots):
                        for b in range(n_batch):
                            instant[field, r, b] = helds[k, field, r, b]
            accumulate(state, instant, ref[0], k, kinds, fields, d_max, stats, pair_stats, record, recording)

    @njit(inline="always", **_OPTIONS)
    def keep_sample(sample, i, x, y, theta, xi, v, omega, singular, sat_v, sat_w):
        """Keep copy i's sample at t_k in column i of ``sample`` (``KEPT_COUNT`` rows, in
        this argument order) until ``add_samples`` adds it to the statistics."""
        sample[0, i], sample[1, i], sample[2, i], sample[3, i], sample[4, i] = x, y, theta, xi, v
        sample[5, i], sample[6, i], sample[7, i], sample[8, i] = omega, singular, sat_v, sat_w

    @njit(inline="always", **_OPTIONS)
    def keep_step_rate(stats, r, c0, c1, k1, wide):
        """Each copy's ``STEP_RATE``: the largest of its rates (``k1``'s row ``RATE_ROW``,
        before ``largest_rate`` overwrites its first slot) times ``wide_substep``. A loop of
        its own: in the stage's loop the load and store cost the kernel ~5 %."""
        for b in range(c0, c1):
            stats[STEP_RATE, r, b] = max(stats[STEP_RATE, r, b], k1[RATE_ROW, b - c0] * wide)

    @njit(inline="always", **_OPTIONS)
    def stage_headings(r, c0, c1, state, step, k_in, widest, trig):
        """sin θ and cos θ at RK4 stage 2, 3 or 4 (θ + δ, δ = step·k_in[θ]) of copies c0 … c1 − 1
        of root r, into ``trig``'s rows 2 and 3, by ``rotated_heading``'s rule: rotated from
        stage 1's (rows 0 and 1), then, only when some |δ| may exceed ``ROTATION_MAX``
        (``widest``: the largest |k_in[θ]|, a NaN counted 0: its stage is NaN either way), the
        full sin/cos of those copies. A loop of its own: the sin/cos is half of a stage's
        dependent chain, and the processor overlaps fewer copies of a longer chain
        (``docs/performance.md``)."""
        for b in range(c0, c1):
            i = b - c0
            trig[2, i], trig[3, i] = stage_rotation(trig[0, i], trig[1, i], step * k_in[2, i])
        if not step * widest <= ROTATION_MAX:   # (every copy's full sin/cos, kept where |δ| is wide:
            for b in range(c0, c1):              # a select, which vectorizes)
                i = b - c0
                sin_t, cos_t = stage_sincos(state[2, r, b] + step * k_in[2, i])
                wide = not abs(step * k_in[2, i]) <= ROTATION_MAX
                trig[2, i], trig[3, i] = (sin_t, cos_t) if wide else (trig[2, i], trig[3, i])

    def time_loop(limited: bool):
        """``roots``' compiled time loop (``run_roots``) for copies with actuator limits
        (``limited``) or for copies without any (every limit inf, which clips nothing: the law's
        command as it is, no saturation flags, the same numbers). Each is compiled on its first
        use: a law's batches without limits never compile the other."""

        @njit(inline="always", **_OPTIONS)
        def root_stage(r, b, fields, limits, x, y, theta, sin_t, cos_t, xi, ref):
            """Copy b of root r at one RK4 stage (sin θ and cos θ given): its rates (ẋ, ẏ, θ̇, ξ̇)
            and command (v, ω, singular, sat v, sat ω); without limits the law's own, as
            ``saturate`` with inf limits returns it (NaN and −0.0 included, no flag)."""
            gains = gains_a(*field_row(fields, r, b)[:n_a])
            if limited:
                v, omega, xi_dot, singular, sat_v, sat_w = law_command(law_a, gains, x, y, theta, sin_t, cos_t, xi, ref,
                                                                       limits[0, r, b], limits[1, r, b])
            else:
                v, omega, xi_dot, singular = law_a(x, y, theta, cos_t, sin_t, xi, ref, gains)
                sat_v, sat_w = 0.0, 0.0
            dx, dy, dtheta = plant_rates(v, omega, cos_t, sin_t)
            return dx, dy, dtheta, xi_dot, v, omega, singular, sat_v, sat_w

        @njit(inline="always", **_OPTIONS)
        def next_stats(old, t, k, v, omega, singular, sat_v, sat_w, err1, err2):
            """``add_sample_`` for a sample at t_k that is not the run's last (stage 1's own loop):
            the final errors are left to the last sample, and without limits the saturation
            counts as they are (their flags are 0). LLVM then drops those rows' stores and loads
            (3 % of a step). So an unrecorded call that stops before t_N (k_stop < n_steps)
            leaves E_FINAL and H_FINAL as they were: they are the run's once its last sample
            is taken (``simulate`` always takes it)."""
            (e_mean, e_m2, e_sq, e_max, _, h_sum, h_sq, h_max, _, v_peak, v_peak_t, w_peak, w_peak_t, v_sq, w_sq,
             sat_v_sum, sat_w_sum, singular_sum, first_singular, sat_any_sum) = add_sample_(
                old, t, k, v, omega, singular, sat_v, sat_w, err1, err2)
            if not limited:
                sat_v_sum, sat_w_sum, sat_any_sum = old[SAT_V], old[SAT_W], old[SAT_ANY]
            return (e_mean, e_m2, e_sq, e_max, old[E_FINAL], h_sum, h_sq, h_max, old[H_FINAL], v_peak, v_peak_t, w_peak,
                    w_peak_t, v_sq, w_sq, sat_v_sum, sat_w_sum, singular_sum, first_singular, sat_any_sum)

        @njit(inline="always", **_OPTIONS)
        def middle_stage(r, c0, c1, state, fields, limits, half, ref, xi_speed, k_in, widest, k_out, peak, trig):
            """RK4 stage 2 or 3 of copies c0 … c1 − 1 of root r: from x + h/2·k_in (k1 or k2, its
            largest |θ̇| ``widest``), at t + h/2 (``ref``), its rates into ``k_out`` (k2 or k3).
            Returns the largest rate so far (``peak``) when measuring, and k_out's largest |θ̇|.
            ``k_in`` and ``k_out`` are arrays of their own, arguments of ``run_roots``: rows of one
            array chosen by a variable left LLVM unable to tell the rows read from the rows
            written, and the loop ran 2.7x slower."""
            stage_headings(r, c0, c1, state, half, k_in, widest, trig)
            for b in range(c0, c1):
                i = b - c0
                x, y = state[0, r, b] + half * k_in[0, i], state[1, r, b] + half * k_in[1, i]
                theta, xi = state[2, r, b] + half * k_in[2, i], state[3, r, b] + half * k_in[3, i]
                dx, dy, dtheta, dxi, v, omega, _, _, _ = root_stage(r, b, fields, limits, x, y, theta, trig[2, i],
                                                                    trig[3, i], xi, ref)
                k_out[0, i], k_out[1, i], k_out[2, i], k_out[3, i] = dx, dy, dtheta, dxi
                k_out[RATE_ROW, i] = tracking_rate(dtheta)
                if measuring:
                    peak = max(peak, stage_rate((x, y, theta, xi, dxi, v, omega), xi_speed))
            return peak, largest_rate(k_out, np.int64(c1 - c0))

        @njit(**NOALIAS, **_OPTIONS)   # (its arrays are distinct: ``roots`` makes the scratch, the simulator the rest)
        def run_roots(workspace, c1, rows, row_start, substeps, xi_speed, dt, k_start, k_stop, n_steps, record,
                      record_at, step_rate):
            """``roots``' time loop for the first c1 copies (unsigned) of one robot, held in
            ``workspace`` (``new_workspace``; its parts named as ``workspace_views`` names them),
            ``record`` the simulator's record, where the workspace's copy b of its robot is
            ``record``'s robot and copy ``record_at`` + (0, b): the whole array, not a slice, so that
            every batch runs one compiled time loop (a slice of it was a C array or not, two
            compilations of this function per law). An RK4 step runs
            stage by stage, one loop over the copies each, ``k1``, ``k2`` and ``k3`` keeping each
            copy's stage rates (rows ẋ, ẏ, θ̇, ξ̇) for the next stages, and ``k1`` its first
            stage's rate too (row ``RATE_ROW``, for ``step_rate``): the body of one stage is
            short enough for the processor to overlap the dependent chains of successive copies,
            which a body of all four stages (longer than its reorder window) was not. The same
            operations as ``root_rk4``, in the same order."""
            r, c0 = 0, np.uint64(0)   # (robot 0 and copy 0 of the workspace's arrays)
            state, stats, fields, limits, sample, k1, k2, k3, trig = workspace_views(workspace)
            for k in range(k_start, k_stop + (1 if k_stop == n_steps else 0)):
                row = row_start[k]
                # The last sample's command is no RK4 step's: stage 1's loop alone takes it (one loop
                # of the law fewer to compile; its stage rates are not used).
                last = k == n_steps
                m = 1 if last else substeps[k]
                h = dt / m
                half, sixth = 0.5 * h, h / 6.0
                wide = 0.0 if last else wide_substep(substeps, k, n_steps, dt)
                # Unrecorded, the sample at t_k goes to the statistics in the first stage's own loop:
                # their stores then overlap the stage's arithmetic. (Never the last: ``next_stats``.)
                inline_sample = record.shape[1] == 0 and not measuring and not last
                for j in range(m):
                    r0 = row_values(rows, row + 2 * j)
                    peak = 0.0
                    if j == 0 and inline_sample:   # stage 1 and the sample at t_k (its command: stage 1's)
                        for b in range(c0, c1):
                            i = b - c0
                            x, y, theta, xi = state[0, r, b], state[1, r, b], state[2, r, b], state[3, r, b]
                            sin_t, cos_t = stage_sincos(theta)
                            dx, dy, dtheta, dxi, v, omega, singular, sat_v, sat_w = root_stage(
                                r, b, fields, limits, x, y, theta, sin_t, cos_t, xi, r0)
                            k1[0, i], k1[1, i], k1[2, i], k1[3, i] = dx, dy, dtheta, dxi
                            trig[0, i], trig[1, i] = sin_t, cos_t
                            err1, err2 = root_errors(posture_a, fields, r, b, x, y, theta, r0)
                            store_stats(stats, r, b, next_stats(robot_stats(stats, r, b), r0[0], k, v, omega, singular,
                                                                 sat_v, sat_w, err1, err2))
                            k1[RATE_ROW, i] = tracking_rate(omega)
                        keep_step_rate(stats, r, c0, c1, k1, wide)
                        peak = largest_rate(k1, np.int64(c1 - c0))
                    else:   # stage 1, its command kept for the sample (``add_samples``)
                        # (the first lines of the two stage-1 loops as one inline function stopped
                        # LLVM vectorizing both: 27 instead of 12 ns per robot-step)
                        for b in range(c0, c1):
                            i = b - c0
                            x, y, theta, xi = state[0, r, b], state[1, r, b], state[2, r, b], state[3, r, b]
                            sin_t, cos_t = stage_sincos(theta)
                            dx, dy, dtheta, dxi, v, omega, singular, sat_v, sat_w = root_stage(
                                r, b, fields, limits, x, y, theta, sin_t, cos_t, xi, r0)
                            k1[0, i], k1[1, i], k1[2, i], k1[3, i] = dx, dy, dtheta, dxi
                            trig[0, i], trig[1, i] = sin_t, cos_t
                            keep_sample(sample, i, x, y, theta, xi, v, omega, singular, sat_v, sat_w)
                            if measuring:
                                k1[RATE_ROW, i] = max(0.0, stage_rate((x, y, theta, xi, dxi, v, omega), xi_speed))
                            else:
                                k1[RATE_ROW, i] = tracking_rate(omega)
                        if not measuring:
                            keep_step_rate(stats, r, c0, c1, k1, wide)
                        peak = largest_rate(k1, np.int64(c1 - c0))
                    if last:
                        add_samples(sample, r, c0, c1, r0, k, posture_a, measuring, fields, stats, record, record_at,
                                    step_rate)
                        break
                    r1, r2 = row_values(rows, row + 2 * j + 1), row_values(rows, row + 2 * j + 2)
                    # (k1's largest rate bounds its |θ̇| = |ω|: ``tracking_rate``, or ``stage_rate``)
                    peak, widest = middle_stage(r, c0, c1, state, fields, limits, half, r1, xi_speed, k1, peak, k2,
                                                peak, trig)
                    peak, widest = middle_stage(r, c0, c1, state, fields, limits, half, r1, xi_speed, k2, widest, k3,
                                                peak, trig)
                    stage_headings(r, c0, c1, state, h, k3, widest, trig)
                    for b in range(c0, c1):   # stage 4 from x + h k3, at t + h, and the step
                        i = b - c0
                        x0, y0, theta0, xi0 = state[0, r, b], state[1, r, b], state[2, r, b], state[3, r, b]
                        x, y, theta, xi = x0 + h * k3[0, i], y0 + h * k3[1, i], theta0 + h * k3[2, i], \
                            xi0 + h * k3[3, i]
                        dx, dy, dtheta, dxi, v, omega, _, _, _ = root_stage(r, b, fields, limits, x, y, theta,
                                                                            trig[2, i], trig[3, i], xi, r2)
                        state[0, r, b] = rk4_sum(x0, sixth, k1[0, i], k2[0, i], k3[0, i], dx)
                        state[1, r, b] = rk4_sum(y0, sixth, k1[1, i], k2[1, i], k3[1, i], dy)
                        state[2, r, b] = rk4_sum(theta0, sixth, k1[2, i], k2[2, i], k3[2, i], dtheta)
                        state[3, r, b] = rk4_sum(xi0, sixth, k1[3, i], k2[3, i], k3[3, i], dxi)
                        if measuring:
                            peak = max(peak, stage_rate((x, y, theta, xi, dxi, v, omega), xi_speed))
                    step_rate[k] = max(step_rate[k], peak)   # (every lone root measures its rates)
                    if j == 0 and not inline_sample:
                        add_samples(sample, r, c0, c1, r0, k, posture_a, measuring, fields, stats, record, record_at,
                                    step_rate)

        return run_roots

    run_limited, run_free = time_loop(True), time_loop(False)

    def roots(state, fields, limits, rows, row_start, substeps, targets, offsets, kinds, order, parents, feeds,
              branch, sin_floor, d_max, xi_speed, dt, hold_every, k_start, k_stop, n_steps, stats, pair_stats,
              record, held, step_rate, held_given):
        """``integrate`` (same arguments) for lone roots under continuous-time control:
        ``run_roots`` over ``ROOTS_CHUNK`` copies at a time, each chunk's rows copied into a
        workspace and back (the time loop without limits when no copy has any: saturation was
        ~9 % of a step, ``docs/performance.md``). A Python loop over the chunks (a call each),
        not a compiled one: a compiled caller optimized and generated ``run_roots``'s code a
        second time (2 s of a fresh install's compiling per law). Unrecorded, the final errors
        (E_FINAL, H_FINAL) are written by the sample at t_N only (``next_stats``)."""
        n_batch = state.shape[2]
        run_roots = run_free if np.isposinf(limits).all() else run_limited
        workspace = new_workspace()
        span = (np.int64(k_start), np.int64(k_stop), np.int64(n_steps))
        kept = tuple(zip(WORKSPACE_FIRST, WORKSPACE_COUNTS, (state, stats, fields, limits)))
        for r in range(state.shape[1]):
            for start in range(0, n_batch, ROOTS_CHUNK):
                stop = min(start + ROOTS_CHUNK, n_batch)
                columns = (slice(None), r, slice(start, stop))
                for first, count, array in kept:
                    workspace[first:first + count, :stop - start] = array[columns]
                # the copy count unsigned: no negative-index wrap-around for LLVM to keep, which
                # would stop it vectorizing the loops over the copies
                run_roots(workspace, np.uint64(stop - start), rows, row_start, substeps, float(xi_speed), float(dt),
                          *span, record, (np.int64(r), np.uint64(start)), step_rate)
                for first, count, array in kept[:2]:   # (fields and limits are only read)
                    array[columns] = workspace[first:first + count, :stop - start]

    roots.time_loop = run_free   # (their compiled code, for a look at it: docs/performance.md)
    roots.limited_time_loop = run_limited

    # Inner compiled functions are closures too: give each an identity that names this
    # kernel's laws, so numba's disk cache finds them in the next process and never mixes
    # two kernels up (see stable_cache_identity).
    identity = f"{law_a._MemoMixin__uuid}|{law_b._MemoMixin__uuid}|{int(followers)}"
    inner = {function.py_func.__name__: function for function in (
        evaluate_at, evaluate, accumulate, follower_stage, substep, update_branches, integrate, score)}
    if not followers:
        inner.update(run_roots=run_limited, run_roots_free=run_free)
    for name, function in inner.items():
        function._set_uuid(f"{__name__}.make_kernel[{identity}].{name}")
    for function in inner.values():   # and every module-level function their code calls
        stable_cache_identity(function)
    if followers:
        return Kernel(integrate, evaluate, score, None, None, None)
    law = (law_a, gains_a, posture_a)
    return Kernel(integrate, evaluate, score, LoneRoot(integrate_alone, law), LoneRoot(score_alone, law), roots)
