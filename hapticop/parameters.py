"""Parameter sets of the control and device libraries, made to be a block's parameters as they are.

A library writes its parameters once, as a frozen dataclass with units in the field names,
defaults and a docstring under each field. A block's pydantic model nests these dataclasses
directly: pydantic validates them from YAML (unknown keys refused, `Annotated` bounds checked)
and the JSON Schema carries their docstrings. The libraries stay free of pydantic and of the
runtime; this module only sets the configuration pydantic reads.
"""

from __future__ import annotations

import dataclasses
from typing import TypeVar, dataclass_transform

T = TypeVar("T")

#: What pydantic reads where a block's parameters hold one of these dataclasses: unknown keys
#: refused, and every number finite (a NaN gain or an infinite limit is a mistake, never a setting;
#: a field that means infinity says so with `Field(allow_inf_nan=True)`).
PYDANTIC_CONFIG = {"extra": "forbid", "use_attribute_docstrings": True, "allow_inf_nan": False}


@dataclass_transform(frozen_default=True, field_specifiers=(dataclasses.field,))
def parameters(cls: type[T]) -> type[T]:
    """A frozen dataclass whose keys are checked and whose field docstrings describe it in the schema."""
    cls.__pydantic_config__ = PYDANTIC_CONFIG  # type: ignore[attr-defined]
    return dataclasses.dataclass(frozen=True)(cls)
