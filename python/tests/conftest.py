"""One local server for the whole test run (starting one per test would cost a second each
with the debug binary); tests that are about the server's own life start their own.

The binary is found as the package finds it: $LASERTAG_BIN (tests/run.sh sets it to
target/debug/lasertag), else the repository's target/release or target/debug build.
"""

from __future__ import annotations

import pytest

import lasertag_env


@pytest.fixture(scope="session")
def server():
    with lasertag_env.LocalServer() as s:
        yield s


@pytest.fixture
def make_env(server):
    """Builds parallel environments on the shared server and closes them after the test."""
    made = []

    def make(**kwargs):
        kwargs.setdefault("server", server)
        env = lasertag_env.parallel_env(**kwargs)
        made.append(env)
        return env

    yield make
    for env in made:
        env.close()
