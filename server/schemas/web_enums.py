"""The service's closed sets as one JavaScript module for the web client.

`python -m server.schemas.web_enums` writes `web/js/generated/enums.js` from the app's OpenAPI
document, so the pages name a run status or a reward source through the schema instead of
typing its string again; `tests/server/api/test_web_enums.py` fails while the checked-in file
differs from what this writes now.
"""

from __future__ import annotations

import json
import re
import sys
from typing import Any

from server.main import WEB, create_app

TARGET = WEB / "js" / "generated" / "enums.js"

ENUMS: dict[str, tuple[str, str]] = {
    "RunStatus": ("RunPublic", "status"),
    "RunMode": ("RunPublic", "mode"),
    "Condition": ("RunCreate", "condition"),
    "Outcome": ("EpisodePublic", "outcome"),
    "Cause": ("EpisodePublic", "cause"),
    "AssociationSource": ("AssociationPublic", "source"),
    "AssociationChange": ("AssociationEvent", "change"),
    "RewardSource": ("RewardPublic", "source"),
    "StimulusLevel": ("StimulusPublic", "level"),
    "Lamp": ("TickEvent", "lamp"),
    "How": ("TickEvent", "how"),
    "KpResolution": ("KpProvenancePublic", "resolution"),
}
"""Each exported name and the schema property whose values it holds, in the schema's order."""

HEADER = """\
// The service's closed sets, from its OpenAPI document (/openapi.json). Written by
// `python -m server.schemas.web_enums`; do not edit: a test fails while this differs from what
// that command writes, or while a page names a value (RunStatus.running) that is not here.
"""


def values(openapi: dict[str, Any], schema: str, prop: str) -> list[str]:
    """The enum of `schema`.`prop`: inline, in an `anyOf` (optional), or behind a `$ref`."""
    schemas = openapi["components"]["schemas"]
    pending = [schemas[schema]["properties"][prop]]
    while pending:
        node = pending.pop(0)
        if "enum" in node:
            return [v for v in node["enum"] if v is not None]
        if "$ref" in node:
            pending.append(schemas[node["$ref"].rsplit("/", 1)[-1]])
        pending.extend(node.get("anyOf", []))
    raise LookupError(f"{schema}.{prop} has no enum in the OpenAPI document")


def identifier(value: str) -> str:
    """A JavaScript property name for `value` ("dp-rare" -> "dp_rare")."""
    return re.sub(r"\W", "_", value)


def render(openapi: dict[str, Any]) -> str:
    """The module's text for this OpenAPI document."""
    blocks = [HEADER]
    for name, (schema, prop) in ENUMS.items():
        members = values(openapi, schema, prop)
        pairs = "".join(f"  {identifier(v)}: {json.dumps(v)},\n" for v in members)
        blocks.append(
            f"/** {schema}.{prop} */\nexport const {name} = Object.freeze({{\n{pairs}}});\n"
        )
    return "\n".join(blocks)


def generate() -> str:
    """The module's text for the app as it is now."""
    return render(create_app().openapi())


def main() -> None:
    """Write the module (`python -m server.schemas.web_enums`)."""
    text = generate()
    TARGET.parent.mkdir(parents=True, exist_ok=True)
    TARGET.write_text(text)
    sys.stdout.write(f"wrote {TARGET.relative_to(WEB.parent)}\n")


if __name__ == "__main__":
    main()
