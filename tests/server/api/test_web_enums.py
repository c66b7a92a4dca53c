"""The web client's enums module (`server/schemas/web_enums.py` -> `web/js/generated/enums.js`)."""

from __future__ import annotations

import re

import pytest

from server.main import WEB, create_app
from server.schemas import web_enums


@pytest.fixture(scope="module")
def openapi() -> dict[str, object]:
    return create_app().openapi()


def test_the_checked_in_module_is_what_the_script_writes_now(openapi: dict[str, object]) -> None:
    written = web_enums.TARGET.read_text()
    assert written == web_enums.render(openapi), (
        f"{web_enums.TARGET.relative_to(WEB.parent)} is out of date with the API's schemas: "
        "run `.venv/bin/python -m server.schemas.web_enums` and commit the file"
    )


def test_the_pages_name_only_values_the_service_has(openapi: dict[str, object]) -> None:
    known = {
        name: {web_enums.identifier(v) for v in web_enums.values(openapi, schema, prop)}
        for name, (schema, prop) in web_enums.ENUMS.items()
    }
    use = re.compile(rf"(?<![\w$.])({'|'.join(known)})\.([A-Za-z_$][\w$]*)")
    unknown = []
    seen = 0
    for path in sorted((WEB / "js").rglob("*.js")):
        if path == web_enums.TARGET:
            continue
        for name, member in use.findall(path.read_text()):
            seen += 1
            if member not in known[name]:
                unknown.append(f"{path.relative_to(WEB)}: {name}.{member}")
    assert seen > 20, "the pages name the service's values through the module"
    assert unknown == []


def test_a_property_without_an_enum_is_refused(openapi: dict[str, object]) -> None:
    with pytest.raises(LookupError, match=r"RunPublic\.id has no enum"):
        web_enums.values(openapi, "RunPublic", "id")


def test_optional_and_referenced_enums_are_read(openapi: dict[str, object]) -> None:
    assert "classic" in web_enums.values(openapi, "RunCreate", "world")  # in an anyOf with null
    assert web_enums.values(openapi, "RewardPublic", "source") == ["trainer", "program", "task"]
    assert web_enums.identifier("dp-rare") == "dp_rare"
