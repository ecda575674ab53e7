"""schemathesis hooks for tests/run.sh: realistic test data.

A match needs a map the server has. Generated map names (any string of a-z 0-9 - _) are
almost never one, so nearly every POST /api/matches would end in 404 and the operations on
a match would never be reached. When the generated body names a map, name a shipped one
instead; inline map objects are left as generated (they exercise the map validator).
"""

import os
import re

import schemathesis

# server/schema.rs MAP_NAME_PATTERN: a name that breaks it is left as generated, so that a
# request meant to be refused (a negative case) still is.
MAP_NAME = re.compile(r"[a-z0-9_-]{1,64}")

SHIPPED_MAPS = ["office", "hallway", "maze", "warehouse"]


@schemathesis.hook
def map_body(ctx, body):
    op = ctx.operation
    if op is None or op.method.upper() != "POST" or op.path != "/api/matches":
        return body
    if isinstance(body, dict) and isinstance(body.get("map"), str) and MAP_NAME.fullmatch(body["map"]):
        # The generated name picks the map, so the choice stays reproducible from the seed.
        name = body["map"]
        body["map"] = SHIPPED_MAPS[sum(map(ord, name)) % len(SHIPPED_MAPS)]
    return body


# Fixture matches that tests/run.sh created: a manual one with API-driven opponents and a
# real-time one with human slots.
FIXTURES = {
    "manual": os.environ.get("LASERTAG_ST_MANUAL"),
    "human": os.environ.get("LASERTAG_ST_HUMAN"),
}


@schemathesis.hook
def map_path_parameters(ctx, path_parameters):
    """Point three of four generated match ids at a fixture match (the fourth stays as
    generated, for the 404s), so that step, command and players act on a real match.
    DELETE is left alone: it would end the fixtures (the links from POST /api/matches
    delete matches the run made itself)."""
    op = ctx.operation
    if op is None or op.method.upper() == "DELETE" or not isinstance(path_parameters, dict):
        return path_parameters
    generated = path_parameters.get("id")
    if isinstance(generated, str) and sum(map(ord, generated)) % 4 != 0:
        kind = "human" if op.path.endswith("/players") else "manual"
        if FIXTURES[kind]:
            path_parameters["id"] = FIXTURES[kind]
    oid = path_parameters.get("oid")
    if isinstance(oid, str) and sum(map(ord, oid)) % 4 != 0:
        path_parameters["oid"] = "o1" if len(oid) % 2 else "o0"
    return path_parameters


# An ONNX model (POST /api/policies) is bytes: generated bodies go as they are (binary
# strings), or as their text, or a JSON dump of anything else; the server refuses all but a
# real model with 400, naming what does not fit.
@schemathesis.serializer("application/onnx")
def onnx_body(ctx, value):
    if isinstance(value, (bytes, bytearray)):
        return bytes(value)
    if isinstance(value, str):
        return value.encode("utf-8", "surrogatepass")
    import json
    return json.dumps(value).encode()
