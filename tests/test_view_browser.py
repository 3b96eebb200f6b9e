"""The page in a real browser (Debian's chromium driven by Playwright): a replay and a running
fleet load, robots move, the link panel shows numbers, a wrong token is refused; screenshots are
saved for a person to look at (NONHOLO_VIEW_SCREENSHOTS=DIR keeps them there)."""
import json
import os
import re
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

pytest.importorskip("aiohttp", reason="the view extra (aiohttp) is not installed")
pytest.importorskip("mcap", reason="the view extra (mcap) is not installed")
playwright = pytest.importorskip("playwright.sync_api", reason="Playwright's Python package is not installed")

from view_fleets import chain  # noqa: E402

from nonholo.fleet.launch import run_fleet  # noqa: E402
from nonholo.sim.simulator import simulate  # noqa: E402
from nonholo.view.data import from_result  # noqa: E402
from nonholo.view.feed import FleetObserver, LatestFeed  # noqa: E402
from nonholo.view.record import read_recording  # noqa: E402
from nonholo.view.server import ViewServer  # noqa: E402

CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]
WAIT_MS = 10_000
NUMBER = re.compile(r"-?\d+\.\d{3}")


def chromium() -> str | None:
    for candidate in (os.environ.get("NONHOLO_CHROMIUM"), "/usr/bin/chromium", shutil.which("chromium"),
                      shutil.which("chromium-browser")):
        if candidate and Path(candidate).is_file():
            return candidate
    return None


@pytest.fixture(scope="module")
def browser():
    executable = chromium()
    if executable is None:
        pytest.skip("no chromium browser installed (Debian: apt-get install -y chromium)")
    with playwright.sync_playwright() as p:
        launched = p.chromium.launch(executable_path=executable, args=CHROMIUM_ARGS, timeout=30_000)
        try:
            yield launched
        finally:
            launched.close()


@pytest.fixture
def page(browser):
    context = browser.new_context(viewport={"width": 1400, "height": 760})
    opened = context.new_page()
    opened.set_default_timeout(WAIT_MS)
    errors = []
    opened.on("pageerror", lambda exc: errors.append(str(exc)))
    try:
        yield opened
    finally:
        context.close()
    assert not errors, errors


def shot(page, tmp_path, name: str) -> Path:
    folder = Path(os.environ.get("NONHOLO_VIEW_SCREENSHOTS") or tmp_path)
    folder.mkdir(parents=True, exist_ok=True)
    path = page.screenshot(path=str(folder / name)) and folder / name
    assert path.stat().st_size > 10_000       # a drawn page, not a blank one
    return path


def view_state(page) -> dict:
    return page.evaluate("() => ({t: window.nonholoView.t, mode: window.nonholoView.mode, "
                         "robots: window.nonholoView.robots})")


def link_rows(page) -> dict:
    return {row.get_attribute("data-link"): row.inner_text() for row in page.query_selector_all("tr.link-row")}


def test_replay_page(page, tmp_path):
    _, scenario = chain(tmp_path, duration=6.0)
    result = simulate(scenario, progress=False)
    replay = from_result(result)
    data = replay.page()
    with ViewServer(lambda: data) as server:
        response = page.goto(server.url)
        assert response.status == 200
        page.wait_for_function("() => window.nonholoView && window.nonholoView.t > 0.5")
        first = view_state(page)
        page.wait_for_function(f"() => window.nonholoView.t > {first['t']} + 0.5")
        second = view_state(page)
        assert first["mode"] == "replay" and set(first["robots"]) == set(result.names)
        assert any(abs(second["robots"][n]["x"] - first["robots"][n]["x"]) > 0.1 for n in result.names)
        rows = link_rows(page)
        assert set(rows) == {"leader->f1"} | {f"f{i}->f{i + 1}" for i in range(1, 7)}
        assert all(len(NUMBER.findall(text)) >= 2 and "Δl" in text and "Δφ" in text for text in rows.values())
        # the slider moves time; the panel shows the result's numbers at that frame
        page.click("#play")                                  # pause
        last = len(data["t"]) - 1
        page.eval_on_selector("#slider", f"(s) => {{ s.value = '{last}'; s.dispatchEvent(new Event('input')); }}")
        page.wait_for_function(f"() => window.nonholoView.t === {data['t'][-1]}")
        text = link_rows(page)["leader->f1"]
        e_l = float(NUMBER.findall(text)[0])
        assert e_l == pytest.approx(result.output_errors("f1")[0][-1], abs=6e-4)
        # follow a robot: the view centres on it
        page.select_option("#follow", "f7")
        page.wait_for_timeout(200)
        centre = page.evaluate("() => [window.nonholoView.view.cx, window.nonholoView.view.cy]")
        assert centre == pytest.approx([result.x[result.index("f7")][-1], result.y[result.index("f7")][-1]],
                                       abs=1e-3)
        shot(page, tmp_path, "replay.png")


def test_live_fleet_page(page, tmp_path):
    _, scenario = chain(tmp_path, duration=6.0)
    feed = LatestFeed()
    with ViewServer(None, feed) as server:
        outcome = {}

        def fleet():
            try:
                outcome["run"] = run_fleet(scenario, transport="inproc", observer=FleetObserver(feed), speed=2.0)
            except BaseException as exc:   # reported by the test below
                outcome["error"] = exc

        runner = threading.Thread(target=fleet)
        runner.start()
        try:
            assert page.goto(server.url).status == 200
            page.wait_for_function("() => window.nonholoView.mode === 'live' && window.nonholoView.t > 0.3")
            first = view_state(page)
            page.wait_for_function(f"() => window.nonholoView.t > {first['t']} + 1.0")
            second = view_state(page)
            moved = [n for n in first["robots"] if abs(second["robots"][n]["x"] - first["robots"][n]["x"]) > 0.05]
            assert len(moved) == 8
            rows = link_rows(page)
            assert len(rows) == 7 and all(len(NUMBER.findall(text)) >= 2 for text in rows.values())
            states = [cell.inner_text() for cell in page.query_selector_all("tr.robot-row td.state")]
            assert len(states) == 8 and set(states) <= {"running", "done"}
            shot(page, tmp_path, "live.png")
            # at the end the page turns into the replay of the run
            runner.join(30)
            assert "error" not in outcome and "run" in outcome
            feed.finish(from_result(outcome["run"].result).page())
            page.wait_for_function("() => window.nonholoView.mode === 'replay'")
        finally:
            runner.join(30)


def test_wrong_token_is_refused(page):
    with ViewServer(lambda: {"mode": "replay", "t": [0.0], "robots": [], "reference": None, "links": {}}) as server:
        for url in (server.url[:-1], server.url.split("?")[0], server.url + "x"):
            response = page.goto(url)
            assert response.status == 403 and page.content().count("forbidden") == 1
            assert "nonholo" not in page.content()


def test_fleet_view_command(page, tmp_path):
    """`nonholo fleet --view` prints the page's address; the page shows the running fleet."""
    path, _ = chain(tmp_path, duration=4.0)
    command = [sys.executable, "-m", "nonholo", "fleet", str(path), "--view", "--speed", "4", "--for", "20",
               "--json", "--record", str(tmp_path / "fleet.mcap")]
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        line = _read_line(process.stderr, time.monotonic() + 60)
        url = re.fullmatch(r"page: (http://127\.0\.0\.1:\d+/\?token=[\w-]+)\n", line).group(1)
        assert page.goto(url).status == 200
        page.wait_for_function("() => Object.keys(window.nonholoView.robots).length === 8", timeout=30_000)
        assert page.goto(url.split("=")[0] + "=wrong").status == 403
        # stdout holds exactly the run's JSON, flushed before the page lingers (--for)
        summary = json.loads(_read_line(process.stdout, time.monotonic() + 30))
        assert set(summary["robots"]) == {"leader"} | {f"f{i}" for i in range(1, 8)}
        assert all(link["lost"] == 0 for link in summary["network"]["links"].values())
        recorded = read_recording(tmp_path / "fleet.mcap")      # written before the JSON
        assert recorded.summary["network"]["links"] == summary["network"]["links"]
        assert recorded.links["f6->f7"]["received"] == summary["network"]["links"]["f6->f7"]["received"] > 0
        assert recorded.t[-1] == pytest.approx(4.0)
    finally:
        process.terminate()
        try:
            process.wait(10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(10)
        process.stdout.close()
        process.stderr.close()


def _read_line(stream, deadline: float) -> str:
    """The next line of a child's output stream, waiting at most until ``deadline``."""
    got = {}
    reader = threading.Thread(target=lambda: got.setdefault("line", stream.readline()), daemon=True)
    reader.start()
    reader.join(max(0.0, deadline - time.monotonic()))
    if "line" not in got:
        raise AssertionError("nonholo fleet --view printed nothing in time")
    return got["line"]
