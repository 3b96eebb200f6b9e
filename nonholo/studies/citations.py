"""What the report cites, explained in the report: the errata of the thesis and the sections
of the corrected specification, summarised here so that the report stands alone (the
package never reads the specification at run time).

Two specification files are cited: ``leader.md`` (leader robot: model, tracking laws,
errata 1–24, the Chapter 5 reproduction) and ``follower-posture.md`` (follower formations
and posture stabilisation: typo list 1–29, reference results). Their errata are numbered
separately, so a citation is resolved against the file a study names (``spec_file`` of its
result) unless it names the file itself ("leader.md §5.1").

``find_citations(text, default_file)`` lists the (file, kind, key) citations in a text;
``link_citations(html, default_file)`` turns them into links to the appendix;
``appendix_html(citations)`` writes the appendix.

>>> sorted(find_citations("errata 23–24 (spec §5.4); follower-posture.md §6 (d)", "leader.md"))
[('follower-posture.md', 'section', '6'), ('leader.md', 'erratum', '23'), ('leader.md', 'erratum', '24'), \
('leader.md', 'section', '5.4')]
"""
from __future__ import annotations

import html
import re

LEADER, FOLLOWER = "leader.md", "follower-posture.md"
FILE_TITLES = {LEADER: "leader.md — leader robot: model, tracking laws, errata, Chapter 5 reproduction",
               FOLLOWER: "follower-posture.md — followers, formations and posture stabilisation"}

# (where in the thesis, problem, correction), summarised from the specification's tables
ERRATA: dict[tuple[str, int], tuple[str, str, str]] = {
    (LEADER, 1): ("Eq 3.10–3.17 vs Eq 4.16", "the error's sign and frame differ between chapters",
                  "use Eq 4.16 (desired − actual, robot frame) for every Chapter 4 law"),
    (LEADER, 2): ("Eq 3.21", "L_f h listed twice", "h, L_f h, …, L_f^(n−1) h"),
    (LEADER, 3): ("Eq 3.32", "the input map gives u2 = v2", "v = v2 + z3 v1, ω = v1"),
    (LEADER, 4): ("Eq 4.18", "(3,3) entry of the drift matrix is 1", "0 (ė3 = u2 exactly)"),
    (LEADER, 5): ("Eq 4.19", "(3,3) entry is 1", "0; with a 1 the pole placement of Eq 4.21–4.22 is false"),
    (LEADER, 6): ("text after Eq 4.19", "“v_d(t) = v and ω_d(t) = ω”", "v_d, ω_d constant"),
    (LEADER, 7): ("Eq 4.21–4.22", "derivation step missing, w_d/ω_d mixed",
                  "k1 = k3 = 2ζa, k2 = b|v_d| with a² = ω_d² + b v_d²"),
    (LEADER, 8): ("Eq 4.27", "sin e3 / e2 · e2", "(sin e3 / e3) e2, as Eq 4.29 has it"),
    (LEADER, 9): ("text after Eq 4.27", "“k1, k3 as in Eq 4.21”", "as in Eq 4.22"),
    (LEADER, 10): ("Eq 4.31", "V̇ = −k1k4 e1² + k3 e3²", "V̇ = −k1k4 e1² − k3 e3²"),
    (LEADER, 11): ("§4.9 text", "singularity attributed to Eq 4.32", "Eq 4.33/4.40 (Eq 4.32 defines the output)"),
    (LEADER, 12): ("Eq 4.35", "offset called b, det A = b", "the offset is d (Eq 4.34), det A = d"),
    (LEADER, 13): ("Eq 4.38", "r_i = z_di + …", "r_i = ż_di + k_pi (z_di − z_i): the feedforward is the derivative"),
    (LEADER, 14): ("Eq 4.39", "ξ = c + d r (no dot)", "ξ̇ = c(q, ξ) + d(q, ξ) r"),
    (LEADER, 15): ("before Eq 4.43", "“differentiating Eq 4.41”", "differentiate Eq 4.42"),
    (LEADER, 16): ("§4.9 claim", "exponential tracking stated globally",
                   "valid only while the compensator state ξ(t) ≠ 0; ξ(0) must be chosen"),
    (LEADER, 17): ("Eq 4.51 / 5.12", "the same gain called k2 and k4", "one law (Eq 4.27) with gain k4"),
    (LEADER, 18): ("Eq 5.1", "“fourth-quadrant inverse tangent”, branch jumps not handled",
                   "four-quadrant atan2; unwrap θ_d or wrap the heading error"),
    (LEADER, 19): ("Table 5.1", "v_d(0) = 0.0125 m/s contradicts Eq 5.2 for every test (0.559, 1, 10.05, 0.5 m/s)",
                   "0.0125 can only be a start-up guard of a numerically differentiated feedforward; “ξ(0) = v(0)” "
                   "means the compensator starts at the reference speed"),
    (LEADER, 20): ("Table 5.2", "DFL row: std 0.0410 but variance 0.00017 (0.0410² = 0.00168)",
                   "one of the two is wrong"),
    (LEADER, 21): ("Table 5.5", "nonlinear row: std 2.8172 but variance 7.9112 (√ = 2.8127)",
                   "a digit transposition; variances are in m², not m"),
    (LEADER, 22): ("§5.3.4", "“begins at the origin (10, 0)”",
                   "the circle begins at (10, 0); the robot starts at the origin; T = 40π ≈ 125.66 s"),
    (LEADER, 23): ("§5.4", "cascaded law's Test 4 failure blamed on ω_d not being persistently exciting",
                   "ω_d ≡ 0.05 rad/s is persistently exciting; the cause is the slow mode −(1 + c3)ω_d²/c2 "
                   "(τ ≈ 900 s ≫ 126 s): the robot stays near the circle's centre"),
    (LEADER, 24): ("§5.4", "stable-tracking failure blamed on ω̇_d not being small",
                   "ω̇_d ≡ 0 on the circle; the causes are the very soft lateral gains (Ky, Kθ in SI units), the "
                   "local nature of the result and the 10 m initial error"),
    (FOLLOWER, 1): ("Eq 2.22", "puts the castor point behind the axle",
                    "castor x_2 = x_f + d cos θ_f, y_2 = y_f + d sin θ_f"),
    (FOLLOWER, 2): ("Eq 2.22 vs 2.27", "(x_2, y_2) names two different points", "rename the castor point P_f"),
    (FOLLOWER, 3): ("Eq 2.23, 2.24", "subscripts printed i for l", "l_lf, x_l, θ_l"),
    (FOLLOWER, 4): ("Eq 2.23", "mixed-sign atan2, no branch stated",
                    "φ = atan2(P_y − y_l, P_x − x_l) − θ_l, wrapped or continuous"),
    (FOLLOWER, 5): ("§2.5.1 / Eq 5.8, 5.10", "the requirement l > 2d contradicts l_d = 2, d = 1 (equality)",
                    "use l_d > 2d or state the true clearance (the distance between axle centres)"),
    (FOLLOWER, 6): ("heading “2.6.3”", "section numbering", "2.5.2"),
    (FOLLOWER, 7): ("Eq 2.28–2.29", "φ_1f, φ_2f, v_1, v_2 used without definition", "define them"),
    (FOLLOWER, 8): ("Eq 4.27", "sin e3 / e2 · e2", "(sin e3 / e3) e2"),
    (FOLLOWER, 9): ("Eq 4.31", "V̇ = −k1k4 e1² + k3 e3²", "V̇ = −k1k4 e1² − k3 e3²"),
    (FOLLOWER, 10): ("Eq 4.51 vs 5.12", "the e2 gain is called k2 in Eq 4.51 but k4 in Eq 5.12",
                     "one name (k2 = 2), constant gains"),
    (FOLLOWER, 11): ("Eq 4.52", "μ = tan⁻¹(y/x) − θ + π: quadrant-blind, no goal translation or rotation, no wrapping",
                     "goal-frame coordinates, atan2, wrapped angles (spec §5.2)"),
    (FOLLOWER, 12): ("§4.10.2", "two subsections numbered 4.10.2", "polar 4.10.2, dynamic 4.10.3"),
    (FOLLOWER, 13): ("Eq 4.55", "raw x, y (the goal must be the origin); ξ(0) ≠ 0 not stated; “exponential "
                     "convergence from any configuration” holds for the position only", "spec §5.3"),
    (FOLLOWER, 14): ("Eq 4.60", "no feedforward of ż_d", "add l̇_d, φ̇_d (needed for moving formations)"),
    (FOLLOWER, 15): ("Eq 4.61", "gain names k_a, k_b swapped relative to Eq 4.60; 1/cos γ and tan γ create a "
                     "removable singularity at cos γ = 0", "the G⁻¹ form of spec §2.2"),
    (FOLLOWER, 16): ("§4.11.1–4.11.2", "ω_l < ω_max", "|ω_l| ≤ ω_max, v_l ≥ v_min > 0"),
    (FOLLOWER, 17): ("Eq 4.62", "l_lf written where l_1f is meant (twice)", "l_1f"),
    (FOLLOWER, 18): ("Eq 4.62", "+ v_2 cos φ_2f cos γ_1 in ω_f", "− v_2 cos φ_2f cos γ_1 (re-derived)"),
    (FOLLOWER, 19): ("Eq 4.62", "v_f divides by cos γ_1", "the symmetric form of spec §3.2, whose only "
                     "singularity is sin(γ1 − γ2) = 0"),
    (FOLLOWER, 20): ("§4.11.2 text", "“expressed using Eq. 2.30” (no such equation)", "Eq 2.28–2.29"),
    (FOLLOWER, 21): ("Eq 5.8, 5.9", "l_U, φ_U, φ_ll", "l_lf, φ_lf"),
    (FOLLOWER, 22): ("Eq 5.9", "a ±π step of the bearing: its direction is undefined under wrapping",
                     "state the branch (continuous: passes behind the leader) or ramp φ_d"),
    (FOLLOWER, 23): ("Eq 5.10", "“3π/2 = (240°)”", "240° = 4π/3"),
    (FOLLOWER, 24): ("Eq 5.10", "bearings listed as l–l parameters (they are not controlled), inconsistent with R2 "
                     "at l = 2", "R2 at l = √13, φ ≈ −73.9° (spec §3.3)"),
    (FOLLOWER, 25): ("Eq 5.11", "k5 in the denominator's exponent: the formula is unbounded and overflows",
                     "g = tanh(k6 e2/2) sin t"),
    (FOLLOWER, 26): ("Eq 5.11", "x_d(0) and the goal translation unstated", "x_d(0) = 0, goal-frame coordinates"),
    (FOLLOWER, 27): ("heading “5.5.3”", "numbering; says the goal is the origin but shows both goals", "5.7.3"),
    (FOLLOWER, 28): ("§5.8", "the polar law “fails” for goal (−10, 10)",
                     "not reproducible with the correct law (spec §5.2)"),
    (FOLLOWER, 29): ("§5.8 / §6", "dynamic FL “achieves the correct goal configuration”",
                     "position only: the heading ends at 180° for goal (−10, 10) from heading 0"),
}

# (title, summary) of the specification's sections
SECTIONS: dict[tuple[str, str], tuple[str, str]] = {
    (LEADER, "1"): ("Model and conventions",
                    "Unicycle ẋ = v cos θ, ẏ = v sin θ, θ̇ = ω. Every tracking law uses the error desired − actual "
                    "rotated into the robot frame, e1 (along track), e2 (cross track), and the heading error "
                    "e3 = θ_d − θ wrapped to (−π, π]; without the wrap a law commands a full extra turn whenever "
                    "the reference heading crosses ±π."),
    (LEADER, "2"): ("Feedforward from the flat outputs",
                    "v_d = |ṗ_d|, θ_d = atan2(ẏ_d, ẋ_d), ω_d = (ẋ_d ÿ_d − ẏ_d ẍ_d)/(ẋ_d² + ẏ_d²), computed exactly "
                    "from the reference curve; singular where the reference stops (v_d = 0)."),
    (LEADER, "3"): ("Controllers", "The six tracking laws in implementable form, with their gains, stability "
                                   "results and singularities (§3.1–3.6)."),
    (LEADER, "3.1"): ("Approximate linearization", "Linearize the error dynamics about e = 0 and place the poles "
                                                  "at −2ζa (×3 after matching), a = √(ω_d² + b v_d²): k1 = k3 = 2ζa, "
                                                  "k2 = b|v_d|. Frozen-time eigenvalues only: local."),
    (LEADER, "3.2"): ("Nonlinear (Samson-type) design", "ω = ω_d + b v_d (sin e3/e3) e2 + k3 e3 with the "
                                                       "Lyapunov function (b/2)(e1² + e2²) + e3²/2: globally "
                                                       "asymptotically stable for persistently moving references."),
    (LEADER, "3.3"): ("Cascaded design", "ω = ω_d + c1 e3 decouples the heading; the cross-track error is then "
                                         "corrected only through ω_d, so a straight line never removes a lateral "
                                         "offset and a slow turn has the slow pole −(1 + c3)ω_d²/c2. c1 = 216.9 "
                                         "makes the law stiff."),
    (LEADER, "3.4"): ("Stable tracking (Kanayama)", "ω = ω_d + v_d(Ky e2 + Kθ sin e3); the lateral loop has "
                                                   "natural frequency v_d√Ky: with Table 5.1's gains in SI units "
                                                   "it is extremely soft. Needs v_d > 0; a local result."),
    (LEADER, "3.5"): ("Offset point", "Input–output linearization of a point d ahead of the axle: the point "
                                      "tracks exactly (ż = r) and the heading is internal dynamics. Not in the "
                                      "thesis's tables."),
    (LEADER, "3.6"): ("Dynamic feedback linearization", "An integrator on the speed (ξ = v) makes the closed loop "
                                                       "exactly ë + kd ė + kp e = 0 per axis while ξ ≠ 0; kp = 1, "
                                                       "kd = 0.7 give ω_n = 1 rad/s, ζ = 0.35. ξ(0) is a design "
                                                       "choice (canonical: v_d(0)); ξ = 0 is singular."),
    (LEADER, "4"): ("Errata", "The thesis's equation errors and their corrections (errata 1–24)."),
    (LEADER, "5"): ("Reproduction of the Chapter 5 leader experiments", "Set-up, results, variants, conclusions "
                                                                       "and the origin of the discrepancies."),
    (LEADER, "5.1"): ("The canonical set-up", "Tests 1–4 as in the thesis, Table 5.1 gains, the robot at the "
                                              "origin with heading 0 in all four tests, ξ(0) = v_d(0), exact "
                                              "feedforward, RK4 with N = 100 000 steps (the stiff cascaded "
                                              "law sub-stepped), statistics of the error norm on the uniform "
                                              "grid (std with ddof 0)."),
    (LEADER, "5.2"): ("Canonical results", "The reference simulation's Tables 5.2–5.5 beside the thesis; "
                                           "RK4 at dt = 0.01 s moves every entry by ≤ 0.3 % except the cascaded "
                                           "law's tiny Test 1–3 errors (up to 6 %)."),
    (LEADER, "5.3"): ("Variants explored", "Agreement score = mean over the 20 cells of |ln(ours/thesis)| "
                                           "(canonical 3.26). Other starts, ξ(0) = 0.0125, unwrapped heading "
                                           "errors (variant E, 2.99) and statistics over the accepted steps of a "
                                           "Simulink-like variable-step solver (2.19, the best): the thesis's "
                                           "Test 4 magnitudes match solver-step statistics. Test 2 DFL and "
                                           "Test 4 cascaded are reproduced; the persistent Test 1–3 errors of "
                                           "the thesis are not, since e = 0 is invariant with exact "
                                           "feedforward."),
    (LEADER, "5.4"): ("The thesis's qualitative conclusions", "“DFL has the lowest mean error in Tests 1–3” is "
                                                               "not reproduced (its soft PD loop absorbs a large "
                                                               "initial velocity error); “cascaded and stable "
                                                               "tracking fail on Test 4” is reproduced for the "
                                                               "cascaded law, partly for stable tracking, for the "
                                                               "reasons of errata 23–24."),
    (LEADER, "5.5"): ("The most likely origin of the discrepancies",
                      "(1) statistics over variable-step solver output (explains the Test 4 magnitudes); "
                      "(2) a numerically differentiated feedforward (Simulink Derivative blocks output 0 at t = 0 "
                      "and lag half a step), which explains Table 5.1's v_d(0) = 0.0125 guard and can produce "
                      "persistent errors; (3) possibly unwrapped heading errors."),
    (FOLLOWER, "1"): ("Conventions", "The castor point lies d ahead of the axle centre; the separation l runs from "
                                     "the leader's axle centre to the follower's castor point; the bearing φ is "
                                     "its direction in the leader's frame (φ = π: straight behind); "
                                     "γ = θ_l + φ − θ_f."),
    (FOLLOWER, "2"): ("The l–φ follower", "Separation–bearing control (§2.1–2.5)."),
    (FOLLOWER, "2.2"): ("l–φ decoupling matrix and law", "det G = d/l: no singularity at cos γ = 0. "
                                                          "v_f = w1 cos γ − l w2 sin γ, ω_f = (w1 sin γ + l w2 cos "
                                                          "γ)/d with w from the linear target dynamics; the closed "
                                                          "loop is exactly l̇ = k1(l_d − l), φ̇ = k2(φ_d − φ) "
                                                          "whatever the leader does, if the follower uses the "
                                                          "leader's actual (v, ω)."),
    (FOLLOWER, "2.3"): ("l–φ internal dynamics", "The follower's heading is internal dynamics, stable for a "
                                                  "leader moving forwards (v_l > 0)."),
    (FOLLOWER, "2.4"): ("l–φ singularities and constraints", "Singular only for d = 0 or l → 0. The thesis's "
                                                              "clearance rule l > 2d is met only with equality by "
                                                              "l_d = 2, d = 1 (axle distance √3 m at φ = π/3). "
                                                              "Speed demands are unbounded: 54.8 m/s and 66 rad/s "
                                                              "at the start of Test 4; real actuators would "
                                                              "saturate."),
    (FOLLOWER, "2.5"): ("Bearing branch", "A commanded bearing change of ±π (Eq 5.9) turns one way or the other "
                                          "depending on whether φ is wrapped (round-off decides) or continuous "
                                          "(the castor point swings behind the leader): state the direction."),
    (FOLLOWER, "3"): ("The l–l follower", "Separation–separation control (§3.1–3.3)."),
    (FOLLOWER, "3.2"): ("l–l decoupling matrix, law and singularity", "det G = d sin(γ2 − γ1): the only "
                                                                      "singularity is the follower's castor point "
                                                                      "collinear with its two leaders; monitor "
                                                                      "|sin(γ1 − γ2)|. The closed loop is exactly "
                                                                      "l̇_i = k_i(l_i,d − l_i)."),
    (FOLLOWER, "3.3"): ("Geometry of thesis Eq 5.10", "The bearings of Eq 5.10 are not outputs of the l–l law. "
                                                      "240°/120° at l1 = l2 = 2 needs R2 2√3 m abeam to the right "
                                                      "of the leader (l = √13, φ ≈ −73.9°): the “wedge”. With R2 "
                                                      "at l = 2, φ = 2π/3 the bearings end near 188° and 270°."),
    (FOLLOWER, "4"): ("Followers of followers", "Output errors do not propagate down a chain; speed demands and "
                                                "heading lags do."),
    (FOLLOWER, "5"): ("Posture stabilisation", "All three laws assume the goal is the origin with heading 0: "
                                               "transform the pose into the goal's frame first (the thesis "
                                               "does not)."),
    (FOLLOWER, "5.1"): ("Smooth time-varying feedback", "The nonlinear tracking law tracking a moving point on "
                                                        "the goal's x-axis, excited by g = tanh(k6 e2/2) sin t "
                                                        "(Eq 5.11 as printed overflows). Converges slowly and "
                                                        "not exponentially; the distance oscillates while it "
                                                        "shrinks."),
    (FOLLOWER, "5.2"): ("Polar-coordinate law", "Distance ψ, angles φ and μ in the goal frame; V = ½ψ² + ½(μ² + "
                                                "k3φ²) proves global asymptotic stability. The thesis's failure "
                                                "for goal (−10, 10) is reproduced only by implementation errors: "
                                                "(a) no goal translation (parks at the origin, 14.14 m away), "
                                                "(b) the distance measured from the world origin while the "
                                                "angles are goal-relative (hovers near the goal, heading ≈ "
                                                "180°)."),
    (FOLLOWER, "5.3"): ("Dynamic-feedback posture regulation", "PD laws on the goal-frame position through the "
                                                               "dynamic compensator: exponential convergence of "
                                                               "the position while ξ ≠ 0; ξ(0) must be non-zero "
                                                               "(±0.1 m/s). The heading is not regulated: it ends "
                                                               "at 0 or 180° depending on the sign of the slow "
                                                               "x-mode."),
    (FOLLOWER, "6"): ("Reference results", "RK4 at dt = 0.01 s: (a) l–φ on Tests 1 and 4, (b) the Eq 5.9 switch "
                                           "(settles in 3.92 s, passes behind the leader), (c) l–l on Tests 1 "
                                           "and 4 and the wedge (nearly singular at t ≈ 7.25 s), (d) the "
                                           "posture laws from (−10, −10) to both goals."),
    (FOLLOWER, "7"): ("Typo and inconsistency list", "The thesis's errors in the follower and posture chapters "
                                                    "(1–29)."),
}

_FILE = r"(?P<file>spec(?:'s)?|leader\.md|follower-posture\.md)"
_SECTION = r"§\d+(?:\.\d+)?(?:–\d+(?:\.\d+)?)?(?:\s*\([a-d]\)(?:\s*(?:[–/,]|and)\s*\([a-d]\))*)?" \
           r"(?:\s+(?:item|variant)\s+\w+)?"
_SECTIONS_RUN = re.compile(_FILE + r"\s+(?P<run>" + _SECTION + r"(?:\s*(?:,|/|and)\s*" + _SECTION + r")*)")
_ERRATA_RUN = re.compile(r"(?P<word>errat(?:um|a))\s+(?P<run>\d+(?:\s*(?:,|–|and)\s*\d+)*)")
_NUMBER = re.compile(r"§(\d+)(?:\.(\d+))?(?:–(\d+)(?:\.(\d+))?)?")


def _file_of(word: str, default_file: str) -> str:
    return word if word.endswith(".md") else default_file


def _section_keys(run: str) -> list[str]:
    keys = []
    for match in _NUMBER.finditer(run):
        major, minor, major2, minor2 = match.groups()
        if major2 and minor and minor2 and major2 == major:
            keys += [f"{major}.{n}" for n in range(int(minor), int(minor2) + 1)]
        elif major2 and not minor:
            keys += [str(n) for n in range(int(major), int(major2) + 1)]
        else:
            keys.append(f"{major}.{minor}" if minor else major)
    return keys


def _numbers(run: str) -> list[int]:
    numbers = []
    for part in re.split(r"\s*(?:,|and)\s*", run):
        if "–" in part:
            low, high = (int(x) for x in part.split("–"))
            numbers += list(range(low, high + 1))
        elif part.strip():
            numbers.append(int(part))
    return numbers


def find_citations(text: str, default_file: str) -> set[tuple[str, str, str]]:
    """Every (file, "erratum" | "section", key) cited in ``text``."""
    found = set()
    for match in _SECTIONS_RUN.finditer(text):
        file = _file_of(match["file"], default_file)
        found |= {(file, "section", key) for key in _section_keys(match["run"])}
    for match in _ERRATA_RUN.finditer(text):
        found |= {(default_file, "erratum", str(n)) for n in _numbers(match["run"])}
    return found


def anchor(file: str, kind: str, key: str) -> str:
    return f"{'spec' if kind == 'section' else 'erratum'}-{file.removesuffix('.md')}-{key.replace('.', '-')}"


def known(citation: tuple[str, str, str]) -> bool:
    file, kind, key = citation
    return (file, int(key)) in ERRATA if kind == "erratum" else (file, key) in SECTIONS


def link_citations(fragment: str, default_file: str) -> str:
    """``fragment`` (HTML) with each known citation in its text linked to the appendix."""
    def sections(match):
        file = _file_of(match["file"], default_file)

        def one(number):
            keys = [k for k in _section_keys(number.group(0)) if (file, k) in SECTIONS]
            if not keys:
                return number.group(0)
            return f'<a class="cite" href="#{anchor(file, "section", keys[0])}">{number.group(0)}</a>'
        return match.group(0)[:match.start("run") - match.start()] + _NUMBER.sub(one, match["run"])

    def errata(match):
        def one(number):
            n = int(number.group(0))
            if (default_file, n) not in ERRATA:
                return number.group(0)
            return f'<a class="cite" href="#{anchor(default_file, "erratum", str(n))}">{n}</a>'
        return match["word"] + match.group(0)[len(match["word"]):].replace(match["run"], re.sub(r"\d+", one,
                                                                                                  match["run"]))

    parts = re.split(r"(<[^>]+>)", fragment)
    inside_link = False
    for i, part in enumerate(parts):
        if part.startswith("<"):
            inside_link = part.startswith("<a ") or (inside_link and not part.startswith("</a"))
            continue
        if not inside_link and ("§" in part or "errat" in part):
            part = _SECTIONS_RUN.sub(sections, part)
            parts[i] = _ERRATA_RUN.sub(errata, part)
    return "".join(parts)


def appendix_html(citations: set[tuple[str, str, str]]) -> str:
    """The appendix: every cited specification section and erratum, summarised, by file."""
    out = ['<p>The report cites the corrected specification of the thesis (two files, whose errata are numbered '
           'separately). What each citation says, in short:</p>']
    for file in (LEADER, FOLLOWER):
        sections = sorted((k for f, kind, k in citations if f == file and kind == "section" and (f, k) in SECTIONS),
                          key=lambda k: [int(x) for x in k.split(".")])
        errata = sorted(int(k) for f, kind, k in citations if f == file and kind == "erratum" and (f, int(k)) in ERRATA)
        if not sections and not errata:
            continue
        out.append(f'<h3 id="spec-{file.removesuffix(".md")}">{html.escape(FILE_TITLES[file])}</h3>')
        if sections:
            out.append("<dl class=\"cites\">")
            for key in sections:
                title, summary = SECTIONS[(file, key)]
                out.append(f'<dt id="{anchor(file, "section", key)}">§{key} {html.escape(title)}</dt>'
                           f"<dd>{html.escape(summary)}</dd>")
            out.append("</dl>")
        if errata:
            rows = "".join(f'<tr id="{anchor(file, "erratum", str(n))}"><td class="num">{n}</td>'
                           f"<td>{html.escape(ERRATA[(file, n)][0])}</td><td>{html.escape(ERRATA[(file, n)][1])}</td>"
                           f"<td>{html.escape(ERRATA[(file, n)][2])}</td></tr>" for n in errata)
            out.append(f"<table class=\"errata\"><caption>Errata cited ({html.escape(file)})</caption><thead><tr>"
                       f"<th>#</th><th>where in the thesis</th><th>problem</th><th>correction</th></tr></thead>"
                       f"<tbody>{rows}</tbody></table>")
    return "\n".join(out)
