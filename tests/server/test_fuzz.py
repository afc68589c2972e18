"""Fuzzing the OpenAPI schema with schemathesis: valid and invalid requests alike never get a 5xx."""

from __future__ import annotations

from typing import Any

import requests
import schemathesis
from hypothesis import HealthCheck, Phase, given, settings
from live_server import LiveServer
from schemathesis import GenerationMode

EXAMPLES_PER_MODE = 150  # a few hundred requests in all: well under a minute


def fuzz(server: LiveServer, mode: GenerationMode, seen: dict[int, int]) -> None:
    schema = schemathesis.openapi.from_url(f"{server.url}/openapi.json")
    session = requests.Session()

    @given(case=schema.as_strategy(generation_mode=mode))
    @settings(
        max_examples=EXAMPLES_PER_MODE,
        deadline=None,
        derandomize=True,
        database=None,
        phases=[Phase.explicit, Phase.generate],
        suppress_health_check=list(HealthCheck),
    )
    def check(case: Any) -> None:
        response = case.call(base_url=server.url, session=session, timeout=30)
        seen[response.status_code] = seen.get(response.status_code, 0) + 1
        assert response.status_code < 500, f"{case.method} {case.formatted_path}: {response.status_code}"

    check()


def test_fuzzing_the_schema_finds_no_server_error(make_server: Any) -> None:
    # One slot, a short queue and quick default runs: accepted fuzz runs end fast and cannot pile up.
    server: LiveServer = make_server(max_concurrent_runs=1, max_queued_runs=2)
    with server.client() as api:
        assert api.put("/api/config", json={"world": "room2", "speed": "max", "max_steps": 3}).status_code == 200
    seen: dict[int, int] = {}
    fuzz(server, GenerationMode.POSITIVE, seen)
    fuzz(server, GenerationMode.NEGATIVE, seen)
    assert sum(seen.values()) >= EXAMPLES_PER_MODE
    assert any(400 <= code < 500 for code in seen)  # the negative cases were refused, not accepted
