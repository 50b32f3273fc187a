"""The interactive API documentation (Swagger UI at /v1/docs, ReDoc at /v1/redoc) is served by the app itself.

Without internet access a page that loads Swagger UI from a CDN is blank: every script, style and
icon the pages name must be a path of this app, and each must answer with its content.
"""

import re

import pytest

URL_ATTR = re.compile(r"""(?:src|href|url)\s*[=:]\s*['"]([^'"]+)['"]""")


def _urls(html: str) -> list[str]:
    return URL_ATTR.findall(html)


@pytest.mark.parametrize("page,script", [("/v1/docs", "swagger-ui-bundle.js"), ("/v1/redoc", "redoc.standalone.js")])
def test_docs_pages_load_their_assets_from_the_app(api, page, script):
    r = api.get(page)
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    html = r.text
    assert not re.search(r"https?://", html), "the page names an outside URL (a CDN, fonts)"
    urls = _urls(html)
    assert f"/v1/docs/assets/{script}" in urls and "/v1/openapi.json" in urls, urls
    for url in urls:
        if url.startswith("/v1/docs/assets/"):
            asset = api.get(url)
            assert asset.status_code == 200 and len(asset.content) > 1000, url
    js = api.get(f"/v1/docs/assets/{script}")
    assert js.headers["content-type"].startswith("text/javascript")
    assert js.text.lstrip()[:200].strip() and "function" in js.text[:200_000]  # JavaScript, not an error page
    assert api.get("/v1/openapi.json").json()["info"]["title"] == "owcsim"


def test_swagger_ui_css_is_served(api):
    css = api.get("/v1/docs/assets/swagger-ui.css")
    assert css.status_code == 200 and css.headers["content-type"].startswith("text/css") and ".swagger-ui" in css.text


def test_only_the_listed_assets_are_served(api):
    for name in ("core.py", "..%2F__init__.py", "nothing.js"):
        r = api.get(f"/v1/docs/assets/{name}")
        assert r.status_code == 404 and r.headers["content-type"] == "application/problem+json", name


def test_docs_routes_stay_out_of_the_openapi_document(api):
    paths = api.get("/v1/openapi.json").json()["paths"]
    assert not [p for p in paths if "docs" in p or "redoc" in p], paths
