"""The console's API page and icon come from the console itself (issue 24: /api/docs was blank
offline, its viewer loaded from a CDN; /favicon.ico was a 404)."""

from __future__ import annotations

import re

from fastapi.testclient import TestClient


def test_the_api_page_and_its_script_load_nothing_from_elsewhere(console: TestClient) -> None:
    page = console.get("/api/docs")
    assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
    script = console.get("/static/apidocs.js")
    assert script.status_code == 200
    for text in (page.text, script.text, console.get("/static/apidocs.css").text):
        assert not re.search(r"(https?:)?//[a-z0-9.-]+\.[a-z]{2,}/", text)  # no address of another host
    assert 'src="/static/apidocs.js"' in page.text
    assert "/api/docs" not in console.get("/api/openapi.json").json()["paths"]


def test_the_favicon_is_served(console: TestClient) -> None:
    icon = console.get("/favicon.ico")
    assert icon.status_code == 200 and icon.headers["content-type"].startswith("image/svg+xml")
    assert icon.text.lstrip().startswith("<svg")
