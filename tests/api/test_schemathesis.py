"""Schemathesis against the live app's own OpenAPI schema: no operation answers a 5xx, and
every answer is one the schema documents (status, content type, body)."""

from __future__ import annotations

import httpx
import pytest
import schemathesis
from hypothesis import HealthCheck, Phase, given, settings
from schemathesis import GenerationMode
from schemathesis.core.result import Ok

from tests.api.conftest import BRAID, WAIT, Live

pytestmark = pytest.mark.slow  # every test here is in the slow tier

EXAMPLES = 25  # per operation and mode: the whole run stays around a minute
CONFIG = schemathesis.Config.from_dict(
    {
        "checks": {
            # a schema-valid program text is still refused when it is not a valid program (422)
            "positive_data_acceptance": {"enabled": False},
            # an oversized body is refused before it is read, with 413
            "negative_data_rejection": {
                "expected-statuses": [400, 401, 403, 404, 405, 406, 409, 413, 415, 422, 428, 429]
            },
        }
    }
)


def test_no_operation_answers_a_server_error(live: Live):
    operator = live.client("operator")
    assert operator.post("/programs", json={"name": "b.bws", "text": BRAID}).status_code == 201
    schema = schemathesis.openapi.from_url(f"{live.base}/openapi.json", config=CONFIG, timeout=WAIT)
    headers = live.headers("operator")
    operations = []
    for result in schema.get_all_operations():
        assert isinstance(result, Ok), result.err()
        operations.append(result.ok())
    assert len(operations) == 17  # GET /whoami, POST /programs/{id}/load, POST /manual among them
    spec = httpx.get(f"{live.base}/openapi.json", timeout=WAIT).json()
    seen: dict[str, set[int]] = {}
    for operation in operations:
        label = f"{operation.method.upper()} {operation.path}"
        declared = spec["paths"][operation.path][operation.method.lower()]
        modes = [GenerationMode.POSITIVE]
        if declared.get("parameters") or declared.get("requestBody"):
            modes.append(GenerationMode.NEGATIVE)  # there is something to get wrong
        for mode in modes:
            _fuzz(live, operation, mode, headers, seen.setdefault(label, set()))
    assert all(seen.values()), seen  # every operation was called
    assert any(409 in codes for codes in seen.values())
    assert live.client("viewer").get("/state").status_code == 200  # still serving


def _fuzz(live, operation, mode, headers, codes: set[int]) -> None:
    @settings(
        max_examples=EXAMPLES,
        deadline=None,
        database=None,
        phases=[Phase.explicit, Phase.generate],
        suppress_health_check=list(HealthCheck),
    )
    @given(case=operation.as_strategy(mode, headers=headers))
    def call(case) -> None:
        response = case.call_and_validate(base_url=live.base, headers=headers, timeout=WAIT)
        codes.add(response.status_code)
        assert response.status_code < 500, (
            case.method,
            case.formatted_path,
            case.body,
            case.query,
            response.status_code,
            response.text,
        )

    call()
