"""The rules every match plays by, as the server states them (``GET /api/rules``): the
laser's beams, field of view and reach, the tag's range, speeds, the tick rate, and the
bounds of the requests' numbers.

An environment asks its server (:func:`fetch`). Without a server (building an
:class:`~lasertag_env.observation.ObservationLayout` by hand, or a server too old to say),
the package's copy stands in (:data:`SHIPPED`, from ``rules.json``, which the server's tests
write from the same declarations, so the two cannot drift apart).
"""

from __future__ import annotations

import json
import math
import numbers
import os

from .client import Client, ServerError

__all__ = ["SHIPPED", "fetch", "check_bound", "check_detections", "check_max_steps", "most_steps"]


def _load_shipped() -> dict:
    with open(os.path.join(os.path.dirname(__file__), "rules.json"), encoding="utf-8") as f:
        return json.load(f)


#: The rules of the server this package was written against (``rules.json``).
SHIPPED: dict = _load_shipped()


def fetch(client: Client) -> dict:
    """The server's rules; the shipped ones from a server without ``GET /api/rules``."""
    try:
        return client.call("GET", "/api/rules")
    except ServerError as e:
        if e.status == 404:
            return SHIPPED
        raise


def check_bound(rules: dict, field: str, value, name: str | None = None) -> None:
    """Raises ``ValueError`` as the server would (``robots: 9 must be in 1..=8``) when
    ``value`` is outside the server's bound of request field ``field`` (``name`` in the
    message, ``field`` by default), NaN included; ``TypeError`` when it is not a number."""
    b = rules["bounds"][field]
    lo, hi = b["minimum"], b["maximum"]
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name or field} must be a number, not {value!r}")
    # Written as the range's membership, which NaN never has (NaN fails both `value < lo`
    # and `value > hi`, so a test for being outside would let it through).
    above = lo < value if b["exclusive_minimum"] else lo <= value
    if not (above and value <= hi and math.isfinite(value)):
        if b["integer"]:
            bound = f"in {int(lo)}..={int(hi)}"
        else:
            bound = f"finite and in {'(' if b['exclusive_minimum'] else '['}{lo:g}, {hi:g}]"
        raise ValueError(f"{name or field}: {value} must be {bound}")


def check_detections(rules: dict, detections) -> None:
    """Raises ``ValueError`` when ``detections`` (slots in the observation vector) is more
    than a match may have opponents (a slot past those would always be empty) or
    negative."""
    if detections is None:
        return
    most = int(rules["bounds"]["opponents"]["maximum"])
    if not 0 <= detections <= most:
        raise ValueError(
            f"detections: {detections} must be in 0..={most} (at most the opponents a "
            "match may have)"
        )


def most_steps(rules: dict) -> int:
    """The most steps an episode may be given (``max_steps``): the ticks of the longest
    match the server starts (``time_limit_s``'s maximum at ``tick_hz``). A step advances at
    least one tick, so no episode ever takes more."""
    return int(rules["bounds"]["time_limit_s"]["maximum"] * rules["tick_hz"])


def check_max_steps(rules: dict, max_steps) -> None:
    """Raises ``ValueError`` when ``max_steps`` (None: no bound but the match's time limit)
    is below 1 or above :func:`most_steps`."""
    if max_steps is None:
        return
    most = most_steps(rules)
    if not 1 <= max_steps <= most:
        raise ValueError(
            f"max_steps: {max_steps} must be in 1..={most} (a step is at least a tick, and "
            "a match lasts at most that many), or None"
        )
