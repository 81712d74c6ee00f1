"""The diagnostics every ``return_info=True`` returns."""

from __future__ import annotations

from typing import Any


class Info(dict[str, Any]):
    """Diagnostics of one computation: a ``dict`` whose keys are also attributes.

    Every ``Info`` has ``converged`` (bool: the stopping rule was met) and ``seconds`` (float:
    wall-clock time of the call); the function that returns it documents its other keys.

    Examples
    --------
    >>> from skinrs import Info
    >>> info = Info(converged=True, seconds=0.5, iterations=12)
    >>> info.iterations, info["converged"]
    (12, True)
    """

    def __getattr__(self, name: str) -> Any:
        try:
            return self[name]
        except KeyError:
            raise AttributeError(f"Info has no entry {name!r}; it has {sorted(self)}") from None

    def __dir__(self) -> list[str]:
        return sorted(set(super().__dir__()) | set(self))
