"""Exceptions a user can act on. Each carries a one-line message that names what is
wrong and what was expected; the CLI prints it and exits with code 2."""
from __future__ import annotations


class NonholoInputError(ValueError):
    """Bad user input: a scenario, a parameter or an expression."""


class ScenarioError(NonholoInputError):
    """A scenario file or object that does not follow the schema.

    ``source`` is the file (or "<scenario>"), ``field`` the dotted path of the offending
    field (for example ``robots[0].gains.kp``).
    """

    def __init__(self, source: str, field: str, problem: str):
        self.source = source
        self.field = field
        self.problem = problem
        where = f"{source}: {field}" if field else source
        super().__init__(f"{where}: {problem}")

    def __reduce__(self):   # pickled with its fields (from a forked helper, a Dask worker)
        return type(self), (self.source, self.field, self.problem), self.__dict__


class ExpressionError(NonholoInputError):
    """A mathematical expression string that cannot be parsed safely. ``formula`` names the
    formula at fault (for example ``"y"`` of a reference) when one is (``formula_of``)."""

    formula: str | None = None


class InfeasibleReferenceError(NonholoInputError):
    """A reference the chosen controller cannot track (for example v_d = 0)."""


class SimulationError(RuntimeError):
    """A simulation that could not produce finite results (for example a law driven
    unstable by too large a step). The CLI prints it on one line and exits with code 1."""


class FormationError(NonholoInputError):
    """A scenario (robot graph) that cannot be simulated; ``robot`` and ``field`` locate the
    problem (the scenario reader turns them into ``robots[i].field`` or ``simulation.field``)."""

    def __init__(self, robot: str | None, field: str, problem: str):
        self.robot, self.field, self.problem = robot, field, problem
        where = f"robot {robot!r}: {field}: " if robot is not None else (f"{field}: " if field else "")
        super().__init__(f"{where}{problem}")

    def __reduce__(self):
        return type(self), (self.robot, self.field, self.problem), self.__dict__


class InputFileError(NonholoInputError):
    """A file or text that cannot be read as input (TOML) within the limits: unreadable,
    too large, not UTF-8, nested too deeply or not valid TOML (``nonholo.tomlfile``).

    ``source`` is the file (or "<scenario>"), ``problem`` what is wrong; readers of a
    schema re-raise it as their own error with ``problem``.
    """

    def __init__(self, source: str, problem: str):
        self.source = source
        self.problem = problem
        super().__init__(f"{source}: {problem}")

    def __reduce__(self):
        return type(self), (self.source, self.problem), self.__dict__
