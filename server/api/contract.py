"""The OpenAPI document as a contract: short operation ids, security, links, event schemas.

FastAPI builds the document from the routes; this adds what it cannot know: which
operations need the bearer token on this service, how the answers of one operation feed
the parameters of the next (create -> start -> reward -> read), and the events the event
stream sends.
"""

from __future__ import annotations

from typing import Any

from fastapi import FastAPI
from fastapi.routing import APIRoute
from pydantic import BaseModel

from server.schemas import STREAM_EVENTS


def operation_id(route: APIRoute) -> str:
    """The route function's name in camelCase: `inject_reward` is `injectReward`."""
    first, *rest = route.name.split("_")
    return first + "".join(word.capitalize() for word in rest)


def _link(operation: str, description: str, **parameters: str) -> dict[str, Any]:
    return {"operationId": operation, "parameters": parameters, "description": description}


_RUN_FROM_BODY = "$response.body#/id"
_RUN_FROM_PATH = "$request.path.run_id"
LINKS: dict[tuple[str, str], dict[str, dict[str, Any]]] = {
    ("createRun", "201"): {
        "startRun": _link("startRun", "start the run just created", run_id=_RUN_FROM_BODY),
        "getRun": _link("getRun", "read the run just created", run_id=_RUN_FROM_BODY),
    },
    ("startRun", "200"): {
        "injectReward": _link("injectReward", "reward the started run", run_id=_RUN_FROM_PATH),
        "getRun": _link("getRun", "read the started run", run_id=_RUN_FROM_PATH),
        "stopRun": _link("stopRun", "stop the started run", run_id=_RUN_FROM_PATH),
        "streamEvents": _link("streamEvents", "follow it live", run_id=_RUN_FROM_PATH),
        "pauseRun": _link("pauseRun", "pause the started run", run_id=_RUN_FROM_PATH),
        "setRunRate": _link("setRunRate", "re-pace the started run", run_id=_RUN_FROM_PATH),
    },
    ("pauseRun", "200"): {
        "stepRun": _link("stepRun", "run one tick of the paused run", run_id=_RUN_FROM_PATH),
        "resumeRun": _link("resumeRun", "tick again", run_id=_RUN_FROM_PATH),
    },
    ("injectReward", "202"): {
        "listRewards": _link("listRewards", "find the reward in the log", run_id=_RUN_FROM_PATH),
        "getLtm": _link("getLtm", "read what it taught the run", run_id=_RUN_FROM_PATH),
    },
    ("stopRun", "200"): {
        "startRun": _link("startRun", "go on from the checkpoint", run_id=_RUN_FROM_PATH),
        "listEpisodes": _link("listEpisodes", "read its episodes", run_id=_RUN_FROM_PATH),
    },
    ("createNetwork", "201"): {
        "getNetwork": _link("getNetwork", "read it (and its ETag)", name="$response.body#/name"),
        "putAssociation": _link(
            "putAssociation", "edit one of its associations", name="$response.body#/name"
        ),
    },
}


def install(app: FastAPI, *, token_needed: bool) -> None:
    """Make `app.openapi()` return the contract (built once, as FastAPI's)."""
    build = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is not None:
            return app.openapi_schema
        doc = build()
        components = doc.setdefault("components", {})
        components.setdefault("securitySchemes", {})["bearer"] = {
            "type": "http",
            "scheme": "bearer",
            "description": "SRLAB_TOKEN. Every write needs it when the service is reachable from "
            "beyond this machine or has a token set"
            + (" (as this one does)." if token_needed else "; this one needs none."),
        }
        schemas = components.setdefault("schemas", {})
        for model in STREAM_EVENTS.values():
            schema = model.model_json_schema(ref_template="#/components/schemas/{model}")
            schemas.update(schema.pop("$defs", {}))
            schemas[_event_schema_name(model)] = schema
        for path, item in doc.get("paths", {}).items():
            for method, op in item.items():
                if not isinstance(op, dict) or "operationId" not in op:
                    continue
                if method != "get":
                    # Writes: the token when this service needs one; else it is optional.
                    op["security"] = [{"bearer": []}] if token_needed else [{}, {"bearer": []}]
                for status, response in op.get("responses", {}).items():
                    links = LINKS.get((op["operationId"], status))
                    if links:
                        response["links"] = links
                if path.endswith("/events"):
                    _describe_stream(op)
                for parameter in op.get("parameters", ()):
                    _absent_not_null(parameter)
        app.openapi_schema = doc
        return doc

    app.openapi = openapi  # type: ignore[method-assign]


def _absent_not_null(parameter: dict[str, Any]) -> None:
    """An optional parameter's schema without FastAPI's `null` branch.

    A query or header parameter is left out, never null: the `null` of `int | None` would
    tell a client that `?expected_version=null` is a value the service takes.
    """
    schema = parameter.get("schema", {})
    branches = schema.get("anyOf")
    if parameter.get("required") or not isinstance(branches, list):
        return
    kept = [b for b in branches if b != {"type": "null"}]
    if len(kept) == 1 < len(branches):
        del schema["anyOf"]
        schema.update(kept[0])


def _event_schema_name(model: type[BaseModel]) -> str:
    return model.__name__


def _describe_stream(op: dict[str, Any]) -> None:
    content = op["responses"]["200"].setdefault("content", {})
    content["text/event-stream"] = {
        "schema": {
            "type": "string",
            "description": "Server-sent events, each `event: <name>` and one line of JSON "
            "`data:`; the events and their data are in `x-events`. The stream does not "
            "end while the run runs: a client reads it event by event.",
        },
        "x-events": {
            name: {"$ref": f"#/components/schemas/{_event_schema_name(model)}"}
            for name, model in STREAM_EVENTS.items()
        },
    }
    content.pop("application/json", None)
