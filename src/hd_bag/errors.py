"""Errors and validation findings of the bag layer."""

from __future__ import annotations

import os
from dataclasses import dataclass


class BagError(ValueError):
    """A bag that cannot be used: the message starts with the file path, then names the problem."""

    def __init__(self, path: str | os.PathLike, problem: str):
        self.path = os.fspath(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")


@dataclass(frozen=True)
class Violation:
    """One finding of :func:`hd_bag.validate_bag`.

    ``severity`` is ``"error"`` (the bag breaks the contract: `hdphm validate`
    fails) or ``"warning"`` (allowed by the contract but worth knowing:
    dropouts, duplicates, a missing optional topic). ``index`` is the
    message's position on its topic in file order (None for file-level
    findings).
    """

    file: str
    topic: str | None
    index: int | None
    problem: str
    severity: str = "error"

    def __str__(self) -> str:
        where = self.file
        if self.topic:
            where += f" {self.topic}"
        if self.index is not None:
            where += f" [{self.index}]"
        return f"{where}: {self.severity}: {self.problem}"
