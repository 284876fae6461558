"""The base of every config model: unknown keys are errors, NaN and infinite numbers are refused, and
values are validated on assignment. A key that moved to another section is refused with its new home."""

from __future__ import annotations

from typing import Any, ClassVar

from pydantic import BaseModel, ConfigDict, ValidationError, model_validator
from pydantic_core import InitErrorDetails, PydanticCustomError


class StrictModel(BaseModel):
    """A config section. Every field carries a description with its unit."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True, frozen=False, allow_inf_nan=False)

    # Keys this section no longer takes, each with the sentence that names its new home and the fix.
    moved_keys: ClassVar[dict[str, str]] = {}

    @model_validator(mode="before")
    @classmethod
    def _refuse_moved_keys(cls, data: Any) -> Any:
        moved = [key for key in cls.moved_keys if isinstance(data, dict) and key in data]
        if moved:
            # Raised at the key itself, so that the config's error names it (render.frame_mode, not render).
            raise ValidationError.from_exception_data(
                cls.__name__,
                [
                    InitErrorDetails(
                        type=PydanticCustomError("moved_key", cls.moved_keys[key]),
                        loc=(key,),
                        input=data[key],
                    )
                    for key in moved
                ],
            )
        return data
