"""The one error type a user sees for bad input: a single line, exit status 2."""


class ScenarioError(ValueError):
    """A scenario, parameter, line or file problem, reported to the user as one line."""
