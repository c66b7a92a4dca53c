"""What every HTTP model shares: strict request bodies, storable text, the health answer."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Annotated, Any, ClassVar, Literal, get_args, get_origin

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    GetJsonSchemaHandler,
    JsonValue,
    ValidationInfo,
    field_validator,
)
from pydantic.json_schema import JsonSchemaValue
from pydantic_core import CoreSchema

from core.text import unstorable


def _kinds(annotation: object) -> set[type]:
    """The plain types among an annotation's (`float | None` -> {float, NoneType})."""
    args = get_args(annotation)
    if not args:
        return {annotation} if isinstance(annotation, type) else set()
    return {t for a in args for t in _kinds(a)} if get_origin(annotation) is not Literal else set()


TEXT_PATTERN = r"^[^\u0000]*$"
"""Text a request may carry, as a JSON Schema pattern: any character but NUL, which
PostgreSQL cannot store (`core.text` holds the rule). Lone surrogates are refused too, but
they are not text at all (no UTF-8 holds one, and most validators' regular expressions
cannot name them), so the pattern leaves them out."""


def _storable(value: str) -> str:
    problem = unstorable(value)
    if problem is not None:
        raise ValueError(problem)
    return value


def _with_text_pattern(schema: JsonSchemaValue) -> None:
    """Give a string schema (or a nullable one's string branch) `TEXT_PATTERN`.

    A schema with its own pattern, enum or constant says more already.
    """
    if {"pattern", "enum", "const"} & schema.keys():
        return
    if schema.get("type") == "string":
        schema["pattern"] = TEXT_PATTERN
    for branch in schema.get("anyOf", ()):
        _with_text_pattern(branch)


class _TextSchema:
    """Annotated metadata: `TEXT_PATTERN` in the JSON schema of the string it marks."""

    def __get_pydantic_json_schema__(
        self, core_schema: CoreSchema, handler: GetJsonSchemaHandler
    ) -> JsonSchemaValue:
        schema = handler(core_schema)
        _with_text_pattern(schema)
        return schema


Text = Annotated[str, AfterValidator(_storable), _TextSchema()]
"""A string the service may store: a query or path parameter's type (a request body's
strings get the same rule from `Strict`). Anything else is a 422 naming the field."""


def _strict_schema(schema: dict[str, Any], model: type) -> None:
    for prop in schema.get("properties", {}).values():
        _with_text_pattern(prop)
    examples = getattr(model, "EXAMPLES", ())
    if examples:
        schema["examples"] = list(examples)


class Strict(BaseModel):
    """A request body: unknown fields are an error, and values are not coerced.

    `"hz": "10"` is a string, not a number, `true` is a boolean, not 1, and `1` is not
    `true`: as JSON Schema reads the document (where 10.0 is an integer, and an integer is
    a number). Floats are finite. Every string field takes `Text`'s rule, declared and
    checked, without saying so: a new field cannot forget it. `EXAMPLES`, when a body has
    them, are its schema's `examples` (the documentation's, and a contract test's first
    cases).
    """

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, json_schema_extra=_strict_schema)
    EXAMPLES: ClassVar[tuple[dict[str, JsonValue], ...]] = ()

    @field_validator("*", mode="before")
    @classmethod
    def _as_json_schema_reads_it(cls, value: object, info: ValidationInfo) -> object:
        assert info.field_name is not None
        kinds = _kinds(cls.model_fields[info.field_name].annotation)
        if kinds & {int, float} and isinstance(value, bool | str):
            raise ValueError(f"a number is needed, not {type(value).__name__} {value!r}")
        if bool in kinds and value is not None and not isinstance(value, bool):
            raise ValueError(f"true or false is needed, not {value!r}")
        if str in kinds and isinstance(value, str):
            _storable(value)
        return value


class Health(BaseModel):
    status: Literal["ok"]
    version: str
    database: str
    runs_active: int
    viser_port: int | None = Field(
        None, description="Port of the 3D view on this host; null when it is not running."
    )
    data_version: str = Field(
        "",
        description="a digest of srlab's data files (core/data: sensors, behaviours, worlds, "
        "networks, conditions) as the service read them at its start",
    )
    data_changed: list[str] = Field(
        default_factory=list,
        description="data files edited, added or removed since the service started, "
        "relative to core/data: it keeps using them as they were until it is restarted",
    )


def one_of(value: str | None, known: Sequence[JsonValue], what: str) -> str | None:
    """`value` if it is one of `known` (or empty), else a ValueError listing them."""
    if value and value not in known:
        raise ValueError(f"unknown {what} {value!r} (known: {', '.join(map(str, known))})")
    return value
