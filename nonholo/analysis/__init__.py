"""Symbolic control analysis of driftless and control-affine systems (thesis Chapter 3).

Exact (sympy) Lie brackets and Lie derivatives, distributions (rank, involutivity,
accessibility filtration, nilpotency), linear controllability at a point, along a trajectory
and in the body frame, observability, chained forms and flatness, for the built-in robot
models and for systems written in TOML. See docs/analysis.md.

Typical use::

    from nonholo.analysis import BUILTIN_SYSTEMS, summarize, render_text
    print(render_text(summarize(BUILTIN_SYSTEMS["unicycle"](), depth=3)))
"""
from .builtin import BUILTIN_SYSTEMS, car, separation_bearing, separation_separation, unicycle, \
    unicycle_trailer
from .chained import check_chained_form, check_flatness, chained_form_rates
from .distributions import (accessibility_filtration, generic_rank, is_involutive,
                            nilpotency_step, rank_loss_conditions)
from nonholo.errors import ExpressionError
from nonholo.expressions import parse_expression
from .lie import bracket_tree, lie_bracket, lie_derivative, repeated_lie_derivatives
from .linear import (body_frame_model, body_frame_rotation, controllability_matrix,
                     linearize, linearize_along_reference, linearize_at_point,
                     similarity_transform, time_varying_controllability_matrix)
from .observability import observability_map, observability_matrix
from .report import RENDERERS, render_json, render_latex, render_markdown, render_text, \
    to_json_dict
from .summary import Summary, summarize
from .system import ChainedFormTransform, ControlSystem, FlatParametrization
from .userfile import SystemFileError, load_system_file

__all__ = [
    "BUILTIN_SYSTEMS", "car", "separation_bearing", "separation_separation", "unicycle",
    "unicycle_trailer", "check_chained_form", "check_flatness", "chained_form_rates",
    "accessibility_filtration", "generic_rank", "is_involutive", "nilpotency_step",
    "rank_loss_conditions", "ExpressionError", "parse_expression", "bracket_tree",
    "lie_bracket", "lie_derivative", "repeated_lie_derivatives", "body_frame_model",
    "body_frame_rotation", "controllability_matrix", "linearize", "linearize_along_reference",
    "linearize_at_point", "similarity_transform", "time_varying_controllability_matrix",
    "observability_map", "observability_matrix", "RENDERERS", "render_json", "render_latex",
    "render_markdown", "render_text", "to_json_dict", "Summary", "summarize",
    "ChainedFormTransform", "ControlSystem", "FlatParametrization", "SystemFileError",
    "load_system_file",
]
