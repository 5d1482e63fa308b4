"""What the validator tells a user: one finding, located in the file, with a hint.

Every check produces `Diagnostic`s rather than raising, so all mistakes in a file are
reported together, each at `file:line:column` with the field path that names it.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field
from enum import Enum


class Severity(str, Enum):
    ERROR = "error"
    WARNING = "warning"


Path = tuple[str | int, ...]


@dataclass(frozen=True)
class Diagnostic:
    """A finding about a composition file.

    `path` addresses the field in the YAML tree (the same keys a JSON Patch would use);
    `rule` is a stable identifier so editors and tests can match on it.
    """

    rule: str
    message: str
    path: Path = ()
    severity: Severity = Severity.ERROR
    expected: str = ""
    hint: str = ""
    file: str = ""
    line: int = 0  # 1-based; 0 when unknown
    column: int = 0  # 1-based; 0 when unknown

    @property
    def dotted_path(self) -> str:
        return ".".join(str(part) for part in self.path) or "<document>"

    def located(self, file: str, line: int, column: int) -> Diagnostic:
        return Diagnostic(**{**asdict(self), "file": file, "line": line, "column": column})

    def to_text(self) -> str:
        where = f"{self.file}:{self.line}:{self.column}" if self.line else (self.file or "<input>")
        text = f"{where}: {self.severity.value}: {self.dotted_path}: {self.message}"
        if self.expected:
            text += f"\n    expected: {self.expected}"
        if self.hint:
            text += f"\n    hint: {self.hint}"
        text += f"\n    [{self.rule}]"
        return text

    def to_json(self) -> dict:
        data = asdict(self)
        data["severity"] = self.severity.value
        data["path"] = list(self.path)
        return data


@dataclass
class Report:
    """All findings for one file."""

    file: str
    diagnostics: list[Diagnostic] = field(default_factory=list)

    @property
    def errors(self) -> list[Diagnostic]:
        return [d for d in self.diagnostics if d.severity is Severity.ERROR]

    @property
    def warnings(self) -> list[Diagnostic]:
        return [d for d in self.diagnostics if d.severity is Severity.WARNING]

    @property
    def ok(self) -> bool:
        return not self.errors

    def extend(self, diagnostics: Iterable[Diagnostic]) -> None:
        self.diagnostics.extend(diagnostics)

    def sorted(self) -> list[Diagnostic]:
        return sorted(self.diagnostics, key=lambda d: (d.line or 10**9, d.column, d.rule))

    def to_json(self) -> dict:
        return {
            "file": self.file,
            "ok": self.ok,
            "errors": len(self.errors),
            "warnings": len(self.warnings),
            "diagnostics": [d.to_json() for d in self.sorted()],
        }


def reports_to_json(reports: list[Report]) -> str:
    return json.dumps({"files": [r.to_json() for r in reports]}, indent=2)
