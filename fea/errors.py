"""The error every model object raises for a bad parameter.

A :class:`ParameterError` is a ``ValueError`` whose message names the parameter, its
value and the valid range, and which also carries the parameter's name, so a caller
(the FEA case, a study config) can say which of *its* keys was wrong without reading
the message.
"""

from __future__ import annotations

__all__ = ["ParameterError"]


class ParameterError(ValueError):
    """A parameter outside its valid range.

    Parameters
    ----------
    parameter : str
        Name of the offending parameter (a field of the object that refused it).
    value : object
        The offending value.
    message : str
        The whole message: parameter, value and the valid range.
    """

    def __init__(self, parameter: str, value: object, message: str):
        super().__init__(message)
        self.parameter = parameter
        self.value = value
