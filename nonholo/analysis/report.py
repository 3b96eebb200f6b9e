"""Reports: every result of ``summarize`` stated and explained, as text, Markdown, LaTeX or
JSON. The prose is built once as a small document (sections of paragraphs and formulas)
and then rendered, so the three human formats say exactly the same thing."""
from __future__ import annotations

import json
import re
from collections.abc import Sequence
from dataclasses import dataclass

import sympy as sp

from .summary import RankResult, Summary

_DISPLAY_SIMPLIFY_LIMIT = 40  # simplify only small expressions: big ones take seconds


@dataclass(frozen=True)
class Formula:
    label: str
    value: sp.Basic


@dataclass(frozen=True)
class Section:
    title: str
    blocks: tuple[str | Formula, ...]


# ----------------------------------------------------------------------------- wording


def conditions_text(rank_loss: Sequence[Sequence[sp.Expr]]) -> str:
    """[[v]] → "v = 0"; [[v_d, omega_d]] → "v_d = 0 and omega_d = 0"; alternatives by "or"."""
    return " or ".join(" and ".join(f"{sp.sstr(e)} = 0" for e in together)
                       for together in rank_loss)


def _rank_sentence(result: RankResult, n: int, what: str) -> str:
    sentence = f"{what} has generic rank {result.rank}"
    sentence += f" = n = {n}" if result.rank == n else f" < n = {n}"
    if result.rank_loss:
        sentence += f"; the rank drops where {conditions_text(result.rank_loss)}"
    return sentence + "."


def _display(expression: sp.Basic) -> sp.Basic:
    def tidy(e):
        return sp.simplify(e) if sp.count_ops(e) <= _DISPLAY_SIMPLIFY_LIMIT else e
    return expression.applyfunc(tidy) if isinstance(expression, sp.MatrixBase) else tidy(expression)


def _names(symbols) -> str:
    return ", ".join(str(s) for s in symbols)


# ----------------------------------------------------------------------------- sections


def system_section(s: Summary) -> Section:
    system = s.system
    blocks: list[str | Formula] = [
        f"{system.description}.",
        f"n = {system.n} states ({_names(system.states)}), m = {system.m} inputs "
        f"({_names(system.inputs)}).",
    ]
    if system.parameters:
        blocks.append("Parameters: " + ", ".join(
            f"{name} (symbolic)" if isinstance(value, sp.Symbol) else f"{name} = {value}"
            for name, value in system.parameters.items()) + ".")
    blocks += [Formula(f"g{i} (input {u})", g)
               for i, (u, g) in enumerate(zip(system.inputs, system.fields), start=1)]
    if system.has_drift:
        blocks += [Formula("drift f", system.drift),
                   "The drift is a known signal (for the followers: the leader's motion, "
                   "frozen at the analysis instant), not a control direction; the brackets "
                   "and the filtration below use the control fields g_i only."]
    return Section("System", tuple(blocks))


def brackets_section(s: Summary) -> Section:
    blocks: list[str | Formula] = [
        "Convention of thesis Eq 2.5: [f, g] = (∂g/∂x) f − (∂f/∂x) g. Left-nested brackets "
        f"of the fields up to length {s.depth} (the Lie-bracket tree; they span all brackets "
        "of the same length)."]
    for level in s.brackets[1:]:
        blocks += [Formula(node.label, node.vector) for node in level]
    return Section("Lie brackets", tuple(blocks))


def involutivity_section(s: Summary) -> Section:
    if s.involutive:
        text = ("Δ = span{g_i} is involutive: every [g_i, g_j] lies in Δ. By Frobenius the "
                "constraints are integrable, so the system is holonomic: it stays on an "
                f"integral manifold of dimension {s.filtration.ranks[0]}. (Thesis §2.2 states "
                "this backwards; involutive means holonomic.)")
    else:
        text = ("Δ = span{g_i} is not involutive: some [g_i, g_j] leaves Δ. By Frobenius the "
                "constraints are not integrable, so the system is nonholonomic: the brackets "
                "generate directions of motion that the inputs cannot produce directly.")
    return Section("Involutivity (Frobenius)", (text,))


def accessibility_section(s: Summary) -> Section:
    n, f = s.system.n, s.filtration
    ranks = ", ".join(f"rank Δ{k} = {r}" for k, r in enumerate(f.ranks, start=1))
    blocks: list[str | Formula] = [f"Accessibility filtration Δ1 ⊂ Δ2 ⊂ … (thesis Eq 3.8): {ranks}."]
    if f.degree is not None:
        blocks.append(
            f"Rank {n} = n is reached at degree {f.degree} with basis {', '.join(f.basis)}: the "
            "Lie algebra rank condition holds at generic points, so by Chow–Rashevskii the "
            "system is locally controllable there (small-time, in every direction)"
            + (" when the drift is absent or switched off." if s.system.has_drift else "."))
    else:
        blocks.append(
            f"Rank {f.rank} < n = {n} up to degree {s.depth}: the reachable set is lower "
            "dimensional (or a larger --depth is needed); the system is not controllable "
            "in every direction from brackets of this length.")
    if s.filtration_at_point is not None:
        at = s.filtration_at_point
        blocks.append(f"At the given point the filtration ranks are {list(at.ranks)}"
                      + (f"; full rank at degree {at.degree}." if at.degree else
                         "; full rank is not reached there (a singular point)."))
    return Section("Accessibility (Chow–Rashevskii / LARC)", tuple(blocks))


def nilpotency_section(s: Summary) -> Section:
    step = s.nilpotency_step
    text = (f"Every bracket of length {step + 1} vanishes identically: the Lie algebra is "
            f"nilpotent of step {step} (as for chained forms, whose brackets above length "
            "n − 1 vanish)." if step is not None else
            f"No level of brackets up to length {s.depth} vanishes: not nilpotent up to this "
            "depth.")
    return Section("Nilpotency", (text,))


def linear_point_section(s: Summary) -> Section:
    system, result = s.system, s.controllability_at_point
    n, m = system.n, system.m
    blocks: list[str | Formula] = [
        "Jacobian linearization δẋ = A δx + B δu at the point p_e with u = 0 (thesis "
        "Eq 3.3–3.6); coordinates not given with --at stay symbolic (suffix _e).",
        Formula("p_e", sp.Matrix([s.point[x] for x in system.states])),
        Formula("A", s.linear_at_point.A), Formula("B", s.linear_at_point.B),
        Formula("C_M = [B AB … A^(n-1)B]", result.matrix),
        _rank_sentence(result, n, "C_M")]
    if result.rank < n:
        blocks.append("The linearization is not controllable, so no linear feedback "
                      "stabilizes the point, not even locally.")
        if not system.has_drift and m < n:
            blocks.append(f"Moreover the system is driftless with m = {m} < n = {n} inputs: "
                          "by Brockett's theorem no smooth (indeed no continuous) time-invariant "
                          "feedback makes a point asymptotically stable. Posture stabilization "
                          "needs time-varying or discontinuous feedback.")
    else:
        blocks.append("The linearization is controllable: linear feedback stabilizes the "
                      "point locally.")
    return Section("Linear controllability at a point", tuple(blocks))


def linear_reference_section(s: Summary) -> Section:
    n, result = s.system.n, s.controllability_along_reference
    blocks: list[str | Formula] = [
        "Linearization along a reference trajectory x_d(t) with reference inputs u_d "
        "(thesis Eq 3.10–3.14), error δx = x − x_d; u_d taken constant.",
        Formula("A(t)", s.along_reference.A), Formula("B(t)", s.along_reference.B),
        "Time-varying controllability (Silverman–Meadows): K0 = B, K_{i+1} = −A K_i + dK_i/dt.",
        Formula("[K0 … K_(n-1)]", result.matrix),
        _rank_sentence(result, n, "The Silverman–Meadows matrix")]
    if result.rank == n:
        blocks.append("The linearization along a moving reference is controllable: linear "
                      "(time-varying) feedback stabilizes trajectory tracking locally"
                      + (f", except where {conditions_text(result.rank_loss)}."
                         if result.rank_loss else "."))
    if s.body_frame is not None:
        blocks += [
            "Similarity transform to body-frame errors, T = rotation by the reference heading "
            "(thesis Eq 3.15–3.17, Appendices D–E): A_R = Ṫ T⁻¹ + T A T⁻¹, B_R = T B.",
            Formula("A_R", s.body_frame.A), Formula("B_R", s.body_frame.B)]
        body = s.controllability_body_frame
        blocks += ([
            "With constant u_d the body-frame model is time-invariant, so the constant "
            "controllability matrix applies.",
            Formula("C_M (body frame, Eq 3.18)", body.matrix),
            _rank_sentence(body, n, "The body-frame C_M")] if body is not None else [
            "The body-frame model still depends on the reference state, so it is time-varying; "
            "the Silverman–Meadows result above is the valid test."])
    return Section("Linear controllability along a trajectory", tuple(blocks))


def observability_section(s: Summary) -> Section:
    system, result = s.system, s.observability
    if result is None:
        return Section("Observability", ("No outputs declared: observability not analysed.",))
    blocks: list[str | Formula] = [
        f"Outputs h = ({_names(system.outputs)}). Observability map Φ = [h; L_f h; …; "
        f"L_f^{system.n - 1} h] with the inputs as constant symbols, as in thesis Eq 3.21–3.27.",
        Formula("Φ", _display(s.observability_map)),
        Formula("∂Φ/∂x", _display(result.matrix)),
        _rank_sentence(result, system.n, "∂Φ/∂x"),
        ("Full rank: the state is locally observable from the outputs and the inputs"
         + (f" wherever {conditions_text(result.rank_loss).replace(' = 0', ' ≠ 0')}."
            if result.rank_loss else ".")) if result.rank == system.n else
        "Not full rank: some state directions cannot be recovered from these outputs."]
    first = s.observability_first_order
    if first is not None:
        blocks += [
            "First-order test with h and L_f h only (the determinant of thesis Eq 3.28 for the "
            "l–φ follower is one of its minors):",
            Formula("∂[h; L_f h]/∂x", _display(first.matrix)),
            _rank_sentence(first, system.n, "∂[h; L_f h]/∂x")
            + (" Where it drops, the higher derivatives may still restore full rank."
               if first.rank_loss else "")]
    if s.observability_rank_at_point is not None:
        blocks.append(f"At the given point ∂Φ/∂x has rank {s.observability_rank_at_point}.")
    return Section("Observability", tuple(blocks))


def chained_section(s: Summary) -> Section | None:
    if not s.chained_forms and s.flatness is None:
        return None
    blocks: list[str | Formula] = []
    for check in s.chained_forms:
        verdict = ("brings the system exactly into the (2, n) chained form ż1 = w1, ż2 = w2, "
                   "ż_k = z_(k−1) w1 (verified symbolically)" if check.is_chained_form else
                   "does NOT give the chained form")
        blocks += [f"{check.reference}: the change of coordinates and inputs {verdict}.",
                   Formula(f"residual ({check.reference})", check.residual),
                   Formula(f"det ∂z/∂x ({check.reference})", check.coordinate_determinant)]
    if s.flatness is not None:
        flat = s.system.flatness
        verdict = ("states and inputs rebuilt from the flat outputs and their derivatives "
                   "satisfy the model identically (checked by substitution): the system is "
                   "differentially flat" if s.flatness.is_flat_parametrization else
                   "the flat parametrization does NOT satisfy the model")
        blocks += [f"Flat outputs ({_names(flat.output_map)}): {verdict}; valid where "
                   f"{flat.validity}.",
                   Formula("states(t)", sp.Matrix(flat.states)),
                   Formula("inputs(t)", sp.Matrix(flat.inputs))]
    return Section("Chained form and flatness", tuple(blocks))


def build_sections(s: Summary) -> list[Section]:
    sections = [system_section(s), brackets_section(s), involutivity_section(s),
                accessibility_section(s), nilpotency_section(s), linear_point_section(s),
                linear_reference_section(s), observability_section(s), chained_section(s)]
    return [section for section in sections if section is not None]


# ----------------------------------------------------------------------------- renderers


def render_text(s: Summary) -> str:
    lines = [f"nonholo analyze: {s.system.name}", ""]
    for section in build_sections(s):
        lines += [section.title, "-" * len(section.title)]
        for block in section.blocks:
            lines += _text_formula(block) if isinstance(block, Formula) else [block]
        lines.append("")
    return "\n".join(lines)


def _text_formula(formula: Formula) -> list[str]:
    value = formula.value
    if isinstance(value, sp.MatrixBase) and value.cols == 1:
        return [f"  {formula.label} = ({', '.join(sp.sstr(e) for e in value)})"]
    if isinstance(value, sp.MatrixBase):
        rows = ["    [" + ", ".join(sp.sstr(e) for e in value.row(i)) + "]"
                for i in range(value.rows)]
        return [f"  {formula.label} ="] + rows
    return [f"  {formula.label} = {sp.sstr(value)}"]


def render_markdown(s: Summary) -> str:
    lines = [f"# nonholo analyze: `{s.system.name}`", ""]
    for section in build_sections(s):
        lines += [f"## {section.title}", ""]
        for block in section.blocks:
            # the label stays outside the math: KaTeX/MathJax lack LaTeX's text-mode escapes
            lines += ([f"`{block.label}` =", "", f"$${sp.latex(block.value)}$$"]
                      if isinstance(block, Formula) else [block])
            lines.append("")
    return "\n".join(lines)


_MATH_SYMBOLS = {
    "θ": r"\theta", "φ": r"\varphi", "ω": r"\omega", "γ": r"\gamma", "Δ": r"\Delta",
    "Φ": r"\Phi", "∂": r"\partial", "≠": r"\neq", "≤": r"\leq", "⊂": r"\subset",
    "∈": r"\in", "·": r"\cdot", "⁻¹": "^{-1}", "ż": r"\dot z", "ẋ": r"\dot x",
    "Ṫ": r"\dot T", "ẏ": r"\dot y", "δ": r"\delta", "²": "^2", "<": "<", ">": ">",
}
_LATEX_TEXT = {
    "\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#", "_": r"\_",
    "{": r"\{", "}": r"\}", "~": r"\textasciitilde{}", "^": r"\^{}",
    "−": "-", "–": "--", "—": "---", "…": r"\dots{}", "§": r"\S{}",
    # \ensuremath, not $…$: two adjacent symbols would otherwise produce "$$"
    **{plain: rf"\ensuremath{{{math}}}" for plain, math in _MATH_SYMBOLS.items()},
}


_LATEX_PATTERN = re.compile("|".join(re.escape(k) for k in sorted(_LATEX_TEXT, key=len,
                                                                     reverse=True)))


def _latex_text(text: str) -> str:
    """Plain report prose as LaTeX text (one pass, so inserted markup is not re-escaped)."""
    return _LATEX_PATTERN.sub(lambda match: _LATEX_TEXT[match.group(0)], text)


def render_latex(s: Summary) -> str:
    lines = [r"\documentclass{article}", r"\usepackage{amsmath}",
             r"\usepackage[margin=2cm]{geometry}", r"\allowdisplaybreaks", r"\begin{document}",
             rf"\section*{{nonholo analyze: {_latex_text(s.system.name)}}}"]
    for section in build_sections(s):
        lines.append(rf"\subsection*{{{_latex_text(section.title)}}}")
        for block in section.blocks:
            lines.append(rf"\[ \text{{{_latex_text(block.label)}}} = {sp.latex(block.value)} \]"
                         if isinstance(block, Formula) else _latex_text(block) + "\n")
    lines.append(r"\end{document}")
    return "\n".join(lines)


def _strings(value: sp.Basic):
    if isinstance(value, sp.MatrixBase):
        return ([sp.sstr(e) for e in value] if value.cols == 1 else
                [[sp.sstr(e) for e in value.row(i)] for i in range(value.rows)])
    return sp.sstr(value)


def _rank_json(result: RankResult | None) -> dict | None:
    if result is None:
        return None
    return {"matrix": _strings(result.matrix), "rank": result.rank,
            "rank_lost_where": conditions_text(result.rank_loss) or None}


def to_json_dict(s: Summary) -> dict:
    """Machine-readable summary; the keys named in issue 5 are at the top level."""
    system = s.system
    brackets = {node.label: _strings(node.vector) for level in s.brackets[1:] for node in level}
    return {
        "system": system.name,
        "description": system.description,
        "n": system.n,
        "m": system.m,
        "states": [str(x) for x in system.states],
        "inputs": [str(u) for u in system.inputs],
        "parameters": {name: sp.sstr(value) for name, value in system.parameters.items()},
        "fields": {f"g{i}": _strings(g) for i, g in enumerate(system.fields, start=1)},
        "drift": _strings(system.drift) if system.has_drift else None,
        "at": {str(k): sp.sstr(v) for k, v in s.at.items()},
        "brackets": brackets,
        "involutive": s.involutive,
        "nonholonomic": not s.involutive,
        "accessibility_rank": s.filtration.rank,
        "accessibility_degree": s.filtration.degree,
        "accessibility_ranks": list(s.filtration.ranks),
        "accessibility_basis": list(s.filtration.basis),
        "accessibility_rank_at_point": s.filtration_at_point.rank if s.filtration_at_point else None,
        "nilpotency_step": s.nilpotency_step,
        "linearization_point": {str(x): sp.sstr(v) for x, v in s.point.items()},
        "linear_controllability_rank_at_point": s.controllability_at_point.rank,
        "linear_at_point": {"A": _strings(s.linear_at_point.A), "B": _strings(s.linear_at_point.B),
                            "controllability": _rank_json(s.controllability_at_point)},
        "linear_along_reference": {
            "A": _strings(s.along_reference.A), "B": _strings(s.along_reference.B),
            "controllability": _rank_json(s.controllability_along_reference)},
        "linear_controllability_rank_along_reference": s.controllability_along_reference.rank,
        "body_frame": None if s.body_frame is None else {
            "A": _strings(s.body_frame.A), "B": _strings(s.body_frame.B),
            "controllability": _rank_json(s.controllability_body_frame)},
        "outputs": [sp.sstr(h) for h in system.outputs],
        "observability_rank": s.observability.rank if s.observability else None,
        "observability_rank_at_point": s.observability_rank_at_point,
        "observability": _rank_json(s.observability),
        "observability_first_order": _rank_json(s.observability_first_order),
        "chained_forms": [{"reference": c.reference, "verified": c.is_chained_form,
                           "residual": _strings(c.residual)} for c in s.chained_forms],
        "flat": None if s.flatness is None else s.flatness.is_flat_parametrization,
    }


def render_json(s: Summary) -> str:
    return json.dumps(to_json_dict(s), indent=2, ensure_ascii=False)


RENDERERS = {"text": render_text, "markdown": render_markdown, "latex": render_latex,
             "json": render_json}
