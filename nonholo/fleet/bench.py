"""Fleet figures (``nonholo bench-fleet``): a leader and 7 followers, one process each, over
TCP on this machine — one-way latency, loss, the highest control rate the 8 processes
sustain, each next to the machine's floor at that moment (``nonholo.fleet.floor``) — and
lockstep control steps per second of the 7-follower chain. Figures to report, asserted
nowhere."""
from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np

from nonholo.fleet.config import load_fleet
from nonholo.fleet.floor import floor_figures
from nonholo.fleet.launch import run_fleet

FOLLOWERS = 7


def star_text(followers: int = FOLLOWERS) -> str:
    """A leader on the circle and ``followers`` l–φ followers of it, spread in bearing."""
    lines = ['name = "star"', "[simulation]", "duration = 2.0", "[reference]", 'kind = "circle"', "[[robots]]",
             'name = "leader"', 'controller = "dynamic-feedback"', "gains = { kp = 1.0, kd = 0.7, xi0 = 0.5 }",
             "start = [0.0, 0.0, 1.5707963267948966]"]
    for i in range(followers):
        phi = math.pi / 2 + math.pi * (i + 1) / (followers + 1)
        lines += ["[[robots]]", f'name = "f{i + 1}"', 'formation = "separation-bearing"', 'leader = "leader"',
                  f"l = {2.0 + 1.5 * i!r}", f"phi = {phi!r}"]
    return "\n".join(lines) + "\n"


def chain_text(followers: int = FOLLOWERS) -> str:
    lines = ['name = "chain"', "[simulation]", "duration = 2.0", "[reference]", 'kind = "eight"', "[[robots]]",
             'name = "leader"', 'controller = "dynamic-feedback"', "gains = { kp = 1.0, kd = 0.7 }",
             "start = [0.0, 0.0, 0.4636476090008061]"]
    for i in range(followers):
        lines += ["[[robots]]", f'name = "f{i + 1}"', 'formation = "separation-bearing"',
                  f'leader = "{"leader" if i == 0 else f"f{i}"}"', "l = 2.0", 'phi = "pi/3"']
    return "\n".join(lines) + "\n"


def _run(folder: Path, name: str, text: str, transport: str, mode: str, **overrides):
    path = folder / f"{name}.toml"
    path.write_text(text)
    scenario, config = load_fleet(path, overrides)
    return run_fleet(scenario, transport, mode, config=config, source=path, overrides=overrides).network


def realtime_figures(network: dict, rate: float) -> dict:
    """Latency and loss over every link, the worst robot's control period, watchdog stops."""
    links = network["links"].values()
    periods = [r["period_s"] for r in network["robots"].values() if r["period_s"]["mean"]]
    return {"rate_hz": rate,
            "latency_p50_ms": 1e3 * float(np.median([l["latency_s"]["p50"] for l in links])),
            "latency_p99_ms": 1e3 * max(l["latency_s"]["p99"] for l in links),
            "latency_max_ms": 1e3 * max(l["latency_s"]["max"] for l in links),
            "sent": sum(l["sent"] for l in links), "lost": sum(l["lost"] for l in links),
            "period_mean_ms": 1e3 * max(p["mean"] for p in periods),
            "period_p99_ms": 1e3 * max(p["p99"] for p in periods),
            "stops": sum(e["event"] == "stop" for r in network["robots"].values() for e in r["watchdog"])}


def sustained(figures: dict) -> bool:
    """A rate is sustained when no state is lost, no watchdog fires, the mean period is within
    5 % of the target and 99 % of periods are under twice the target."""
    period = 1e3 / figures["rate_hz"]
    return (figures["lost"] == 0 and figures["stops"] == 0 and figures["period_mean_ms"] <= 1.05 * period
            and figures["period_p99_ms"] <= 2 * period)


def fault_figures(folder: Path, duration: float = 3.0, signal_name: str = "SIGKILL") -> dict:
    """Leader + 7 followers in realtime over TCP at 50 Hz; the leader is sent ``signal_name``
    1 s into the run. Per follower: the time from the signal to its watchdog's stop and to
    standstill (v and ω held at zero), in ms."""
    import os
    import signal
    import time

    from nonholo.fleet.process import read_trace
    from nonholo.fleet.spawn import start_robot_processes

    path = folder / "faults.toml"
    path.write_text(star_text().replace("duration = 2.0", f"duration = {duration!r}"))
    overrides = {"dt": 0.01, "control_period": 0.02}
    scenario, _ = load_fleet(path, overrides)
    robots = start_robot_processes(path, scenario, None, overrides, 20.0,
                                   extra={n: ["--mode", "realtime"] for n in scenario.names})
    followers = scenario.names[1:]
    try:
        deadline = time.monotonic() + 30.0
        while not all("running at" in (robots.workdir / f"{n}.err").read_text(errors="replace")
                      for n in scenario.names):
            if time.monotonic() > deadline:
                raise RuntimeError("the robots did not start within 30 s")
            time.sleep(0.02)
        time.sleep(1.0)
        sig = getattr(signal, signal_name)
        sent = time.monotonic()
        os.killpg(robots.processes["leader"].pid, sig)
        if sig == signal.SIGSTOP:
            time.sleep(1.0)
            os.killpg(robots.processes["leader"].pid, signal.SIGCONT)
        robots.wait(duration + 30.0, allowed=frozenset({"leader"}))
        stop_ms, still_ms = [], []
        for name in followers:
            _, helds, report = read_trace(robots.workdir / f"{name}.npz")
            stops = [e for e in report["events"] if e["event"] == "stop" and e["at"] > sent]
            if stops:
                stop_ms.append(1e3 * (stops[0]["at"] - sent))
                start = report["events"][0]["at"] - report["events"][0]["t"]
                k = int((stops[0]["at"] - start) / scenario.dt)
                zero = np.flatnonzero((helds[k:, 0] == 0) & (helds[k:, 1] == 0))
                if zero.size:
                    still_ms.append(1e3 * ((k + zero[0]) * scenario.dt + start - sent))
    finally:
        robots.discard()
    return {"signal": signal_name, "followers": len(followers), "stopped": len(stop_ms),
            "stop_ms_max": max(stop_ms) if stop_ms else None,
            "stop_ms_mean": float(np.mean(stop_ms)) if stop_ms else None,
            "standstill_ms_max": float(max(still_ms)) if still_ms else None}


def run_bench(rates=(100, 200, 400, 800), duration: float = 3.0, progress=None, faults: bool = True,
              latency_only: bool = False) -> dict:
    """Every figure (``latency_only``: the realtime TCP ones and their floors alone)."""
    say = progress or (lambda message: None)
    figures = {}
    with tempfile.TemporaryDirectory(prefix="nonholo-bench-") as folder:
        folder = Path(folder)
        if not latency_only:
            figures["lockstep_steps_per_s"] = lockstep_figures(folder, say)
        figures["realtime_tcp"] = realtime_trials(folder, rates, duration, say)
        passed = [t["rate_hz"] for t in figures["realtime_tcp"] if t["sustained"]]
        figures["highest_sustained_hz"] = max(passed) if passed else None
        if latency_only:
            return figures
        try:
            import zenoh  # noqa: F401
        except ImportError:
            figures["realtime_zenoh_100hz"] = None
        else:
            say(f"realtime leader + {FOLLOWERS} followers over Zenoh at 100 Hz")
            network = _run(folder, "star", star_text(), "zenoh", "realtime", duration=duration, dt=0.01,
                           control_period=0.01)
            figures["realtime_zenoh_100hz"] = realtime_figures(network, 100)
        if faults:
            figures["faults"] = []
            for name in ("SIGKILL", "SIGSTOP"):
                say(f"realtime leader + {FOLLOWERS} followers at 50 Hz, leader sent {name}")
                figures["faults"].append(fault_figures(folder, signal_name=name))
    return figures


def lockstep_figures(folder: Path, say) -> dict:
    """Control steps per second of the lockstep 7-follower chain, in process and over TCP."""
    lockstep = {}
    for transport in ("inproc", "tcp"):
        network = _run(folder, "chain", chain_text(), transport, "lockstep", duration=20.0, dt=0.01,
                       control_period=0.02)
        lockstep[transport] = network["control_steps_per_s"]
        say(f"lockstep 7-follower chain over {transport}: {network['control_steps_per_s']:.0f} steps/s")
    return lockstep


def realtime_trials(folder: Path, rates, duration: float, say) -> list[dict]:
    """Per rate, the realtime star over TCP, then the machine's floor at that rate (right
    after, so under the same load)."""
    trials = []
    for rate in rates:
        say(f"realtime leader + {FOLLOWERS} followers over TCP at {rate:g} Hz, then the floor")
        period = 1.0 / rate
        network = _run(folder, "star", star_text(), "tcp", "realtime", duration=duration, dt=period,
                       control_period=period)
        trial = realtime_figures(network, rate)
        trial["sustained"] = sustained(trial)
        trial["floor"] = floor_figures(rate, duration, FOLLOWERS)
        trials.append(trial)
    return trials


def format_bench(figures: dict) -> str:
    """The figures as lines of at most 100 columns."""
    lines = []
    if "lockstep_steps_per_s" in figures:
        lines.append("lockstep 7-follower chain: " + ", ".join(f"{t} {v:.0f} steps/s"
                                                          for t, v in figures["lockstep_steps_per_s"].items()))
    lines.append(f"{'rate Hz':>8} {'lat p50':>8} {'p99':>7} {'max':>7} {'sent':>6} {'lost':>5} {'period':>7} "
                 f"{'p99':>7} {'stops':>5} {'sustained':>9} {'floor p50':>9} {'p99':>6}  (ms)")
    for t in figures["realtime_tcp"]:
        floor = t["floor"]
        lines.append(f"{t['rate_hz']:>8g} {t['latency_p50_ms']:8.3f} {t['latency_p99_ms']:7.3f} "
                     f"{t['latency_max_ms']:7.2f} {t['sent']:>6} {t['lost']:>5} {t['period_mean_ms']:7.3f} "
                     f"{t['period_p99_ms']:7.3f} {t['stops']:>5} {'yes' if t['sustained'] else 'no':>9} "
                     f"{floor['latency_p50_ms']:9.3f} {floor['latency_p99_ms']:6.3f}")
    lines.append(f"highest sustained control rate of 8 processes: {figures['highest_sustained_hz']} Hz")
    lines.append("floor: 1 -> 7 minimal processes, stamps over TCP at the same rate right after "
                 "(what the OS adds)")

    def ms(value):
        return "-" if value is None else f"{value:.0f}"

    for fault in figures.get("faults", []):
        lines.append(f"leader {fault['signal']}: {fault['stopped']} of {fault['followers']} followers stopped by "
                     f"their watchdogs within {ms(fault['stop_ms_max'])} ms")
        lines.append(f"  (mean {ms(fault['stop_ms_mean'])} ms); standstill within {ms(fault['standstill_ms_max'])} ms")
    zenoh = figures.get("realtime_zenoh_100hz")
    if zenoh:
        lines.append(f"Zenoh at 100 Hz: latency p50 {zenoh['latency_p50_ms']:.3f} ms, "
                     f"p99 {zenoh['latency_p99_ms']:.3f} ms, {zenoh['lost']} of {zenoh['sent']} states lost, "
                     f"{zenoh['stops']} watchdog stops")
    return "\n".join(lines)
