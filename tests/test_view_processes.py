"""The live page of a fleet of robot processes, in a real browser (as test_view_browser): with
`nonholo fleet --view` over TCP the robots move on the page and the link panel shows numbers; a
wrong token is refused; `nonholo view --attach` shows a fleet already running (realtime, with its
latencies). A screenshot of each page is saved (NONHOLO_VIEW_SCREENSHOTS=DIR keeps them)."""
import json
import math

import pytest

from test_view_browser import NUMBER, browser, link_rows, page, shot, view_state  # noqa: F401
from process_fleets import free_port, running
from view_fleets import chain, chain_toml

from nonholo.fleet.launch import run_fleet

URL = r"page: (http://127\.0\.0\.1:\d+/\?token=[\w-]+)"
START_S = 60.0      # 8 robot processes starting on a loaded machine
WAIT_MS = 30_000
ROBOTS = {"leader"} | {f"f{i}" for i in range(1, 8)}


@pytest.fixture(scope="module", autouse=True)
def compiled(tmp_path_factory):
    """Compile what the robot processes run (numba caches it on disk) before they start."""
    _, scenario = chain(tmp_path_factory.mktemp("compile"), duration=0.2)
    run_fleet(scenario, "inproc")


def watch_it_move(page, url: str, seconds: float = 0.5) -> dict:
    """Open the page; once every robot shows, check that every one moves; the newest state."""
    assert page.goto(url).status == 200
    page.wait_for_function("() => window.nonholoView.mode === 'live' && window.nonholoView.t > 0.2 && "
                           "Object.keys(window.nonholoView.robots).length === window.nonholoView.page.robots.length",
                           timeout=WAIT_MS)
    first = view_state(page)
    page.wait_for_function(f"() => window.nonholoView.t > {first['t']} + {seconds}", timeout=WAIT_MS)
    second = view_state(page)
    def moved(name: str) -> float:
        return math.dist(*((r["robots"][name]["x"], r["robots"][name]["y"]) for r in (first, second)))
    assert {name for name in first["robots"] if moved(name) > 0.02} == set(first["robots"])
    return second


def test_tcp_fleet_view(page, tmp_path):
    path, _ = chain(tmp_path, duration=3.0)
    with running(["fleet", str(path), "--view", "--speed", "2", "--for", "30", "--json"]) as (_, out, err):
        url = err.wait_for(URL, START_S).group(1)
        watch_it_move(page, url)
        rows = link_rows(page)
        assert len(rows) == 7 and all(len(NUMBER.findall(text)) >= 2 for text in rows.values())
        states = [cell.inner_text() for cell in page.query_selector_all("tr.robot-row td.state")]
        assert len(states) == 8 and set(states) <= {"running", "done"}
        shot(page, tmp_path, "live-tcp.png")
        for wrong in (url[:-1], url.split("?")[0], url + "x"):
            response = page.request.get(wrong)
            assert response.status == 403 and response.text() == "forbidden"
        summary = json.loads(out.wait_for(r"^\{.*", START_S).group(0))
        assert summary["network"]["transport"] == "tcp" and set(summary["robots"]) == ROBOTS
        page.wait_for_function("() => window.nonholoView.mode === 'replay'", timeout=WAIT_MS)


def test_attach_to_a_running_realtime_fleet(page, tmp_path):
    path = tmp_path / "chain.toml"
    path.write_text(chain_toml(4.0, followers=3))          # fewer processes: two commands start here
    keys, address = tmp_path / "fleet.keys", f"127.0.0.1:{free_port()}"
    fleet = ["fleet", str(path), "--mode", "realtime", "--observe", address, "--keys", str(keys), "--json"]
    with running(fleet) as (_, fleet_out, fleet_err):
        fleet_err.wait_for(r"wrote .*fleet\.keys", START_S)
        with running(["view", str(path), "--attach", address, "--keys", str(keys), "--for", "40"]) as (_, out, err):
            url = out.wait_for(URL, START_S).group(1)
            err.wait_for(f"attached on {address}", START_S)
            watch_it_move(page, url)
            page.wait_for_function("() => Object.values(window.nonholoView.links).every((l) => l.latency_s > 0)",
                                   timeout=WAIT_MS)
            rows = link_rows(page)
            assert len(rows) == 3 and all(len(NUMBER.findall(text)) >= 3 for text in rows.values())
            shot(page, tmp_path, "attached-realtime.png")
            summary = json.loads(fleet_out.wait_for(r"^\{.*", START_S).group(0))
            assert summary["network"]["mode"] == "realtime" and set(summary["robots"]) == {"leader", "f1", "f2", "f3"}
