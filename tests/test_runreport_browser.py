"""The main job's report.html in a real headless browser (Debian's chromium driven by Playwright): it loads with
no console error and no network request, every figure renders, and hovering a point of the verified Pareto front
shows that design's parameters.

Needs ``/usr/bin/chromium`` (or ``chromium`` on PATH) and the ``playwright`` package (test extras); Playwright's own
browser download is never used. Without them these tests skip, saying so; with ``DELTAJAX_REQUIRE_BROWSER=1``
(set by ``.ci/run``, which installs chromium) they fail instead.
"""

import os
import shutil

import numpy as np
import pytest

from deltajax.io import load

#: the page is the session's toy main-job run's report (minutes to make, cold)
pytestmark = pytest.mark.slow

#: chromium's switches for a sandbox-less, offline, headless container run; SwiftShader (software WebGL) draws the
#: 3-D workspace view without a GPU
LAUNCH_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
               "--disable-background-networking", "--disable-component-update", "--disable-sync",
               "--enable-unsafe-swiftshader"]


def _chromium():
    exe = "/usr/bin/chromium" if os.path.exists("/usr/bin/chromium") else shutil.which("chromium")
    problem = None if exe else "no chromium (apt-get install chromium)"
    if exe:
        try:
            import playwright.sync_api  # noqa: F401
        except ImportError:
            problem = "the playwright package is not installed (pip install -e '.[test]')"
    if problem:
        if os.environ.get("DELTAJAX_REQUIRE_BROWSER") == "1":
            pytest.fail(f"DELTAJAX_REQUIRE_BROWSER=1 but {problem}")
        pytest.skip(problem)
    return exe


@pytest.fixture(scope="module")
def page(toy_run, tmp_path_factory):
    """The toy main-job run's report.html (a copy) open in headless chromium, with the console errors, page
    errors and non-file requests it produced while loading."""
    exe = _chromium()
    from playwright.sync_api import sync_playwright

    src = toy_run("ga_reconfig")
    d = tmp_path_factory.mktemp("report_browser")
    shutil.copy(src.parent / "report.html", d / "report.html")
    errors, requests = [], []
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=exe, args=LAUNCH_ARGS, headless=True)
        try:
            pg = browser.new_page(viewport={"width": 1300, "height": 1000})
            pg.on("console", lambda m: errors.append(f"console {m.type}: {m.text}") if m.type == "error" else None)
            pg.on("pageerror", lambda e: errors.append(f"page error: {e}"))

            def route(r):
                if not r.request.url.startswith("file://"):
                    requests.append(r.request.url)
                    return r.abort()
                return r.continue_()

            pg.route("**/*", route)
            pg.goto((d / "report.html").as_uri(), wait_until="load")
            pg.wait_for_function("document.querySelectorAll('.js-plotly-plot').length === 3", timeout=60_000)
            yield {"page": pg, "errors": errors, "requests": requests, "data": load(src), "dir": d}
        finally:
            browser.close()


def test_loads_offline_without_console_errors(page):
    assert page["errors"] == []
    assert page["requests"] == []


def test_every_figure_renders(page):
    pg = page["page"]
    for key in ("fig-front", "fig-torque"):
        n = pg.evaluate(f"document.querySelectorAll('#{key} .main-svg .scatterlayer .trace').length")
        assert n >= 3, (key, n)
        pts = pg.evaluate(f"document.querySelectorAll('#{key} .scatterlayer path.point').length")
        assert pts > 0, key
    # the 3-D view draws into a WebGL canvas of real size, and reports no WebGL failure
    size = pg.evaluate("(() => { const c = document.querySelector('#fig-workspace canvas');"
                       " return c ? [c.width, c.height] : null; })()")
    assert size is not None and min(size) > 100, size
    assert pg.evaluate("document.querySelector('#fig-workspace').innerText.includes('WebGL')") is False
    assert pg.evaluate("document.getElementById('fig-workspace')._fullLayout.scene._scene !== undefined")


def test_hovering_a_front_point_shows_its_parameters(page):
    pg, V = page["page"], page["data"]["verify"]
    names = [str(n) for n in V["design_name"]]
    front = np.asarray(V["front"], int)
    # the screen position of the front trace's first point, from the figure's own axes
    where = pg.evaluate("""(() => {
        const gd = document.getElementById('fig-front');
        const i = gd._fullData.findIndex(t => t.name === 'verified Pareto front');
        const t = gd._fullData[i], xa = gd._fullLayout.xaxis, ya = gd._fullLayout.yaxis;
        const r = gd.getBoundingClientRect();
        return {x: r.left + xa._offset + xa.l2p(t.x[0]), y: r.top + ya._offset + ya.l2p(t.y[0]),
                text: t.hovertext[0]};
    })()""")
    pg.mouse.move(where["x"] - 30, where["y"] - 30)
    pg.mouse.move(where["x"], where["y"], steps=5)
    pg.wait_for_selector("#fig-front .hoverlayer .hovertext", timeout=10_000)
    shown = pg.evaluate("Array.from(document.querySelectorAll('#fig-front .hoverlayer .hovertext tspan.line'))"
                        ".map(t => t.textContent).join('\\n')")
    name = shown.splitlines()[0].split(" ")[0]
    assert name in {names[i] for i in front}, shown
    i = names.index(name)
    params = [line for line in shown.splitlines() if ":" in line]
    for j, p in enumerate(page["data"]["verify"]["params"][i]):
        assert any(f"{p:.5g}" in line for line in params), (p, shown)
    assert f"picks_per_min: {V['picks_per_min'][i]:.5g} 1/min" in shown
    assert "constraint values" in shown and "gear_ratio" in shown

