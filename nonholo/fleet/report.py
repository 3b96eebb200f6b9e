"""What a fleet run reports beyond the simulator's result: the link-health figure and a
terminal summary of the network section (at most 100 columns)."""
from __future__ import annotations

import numpy as np


def link_timelines(reports: list[dict]) -> dict:
    """Per link "parent->child": (times s, age s of the parent state used) at each control
    instant the child had one; per robot its watchdog and link events."""
    links = {}
    for report in reports:
        for parent in report["parents"]:
            links[f"{parent}->{report['name']}"] = (np.asarray(report["age_times"].get(parent, [])),
                                                   np.asarray(report["ages"].get(parent, [])))
    return {"links": links, "events": {r["name"]: r["events"] for r in reports}}


def plot_link_health(timelines: dict, network: dict, path) -> None:
    """One figure: per link the age of the state used over time (a gap: none usable), with
    the robots' watchdog stops and resumes marked; beside it per link states sent, received,
    lost and frames rejected."""
    from nonholo.sim.plotting import plt

    figure, (ages, counts) = plt.subplots(1, 2, figsize=(12, 4.5), gridspec_kw={"width_ratios": [3, 2]})
    for name, (times, values) in timelines["links"].items():
        if len(times):
            ages.plot(times, np.asarray(values) * 1e3, lw=1, label=name)
    if network.get("stale_after"):
        ages.axhline(network["stale_after"] * 1e3, color="grey", lw=0.8, label="stale_after")
    marks = {"stop": ("tab:red", "--"), "resume": ("tab:green", ":")}
    for robot, events in timelines["events"].items():
        for event in events:
            if event["event"] in marks:
                color, style = marks[event["event"]]
                ages.axvline(event["t"], color=color, ls=style, lw=0.8)
    ages.set_xlabel("time [s]")
    ages.set_ylabel("age of the parent state used [ms]")
    ages.set_title("link health (red dashed: watchdog stop, green dotted: resume)", fontsize=10)
    if timelines["links"]:
        ages.legend(fontsize=7, ncol=2)
    names = list(network["links"])
    y = np.arange(len(names))
    for offset, (key, color) in enumerate((("sent", "tab:blue"), ("received", "tab:green"), ("lost", "tab:orange"),
                                           ("rejected", "tab:red"))):
        counts.barh(y + (offset - 1.5) * 0.2, [network["links"][n][key] for n in names], height=0.2, color=color,
                    label=key)
    counts.set_yticks(y, names, fontsize=8)
    counts.invert_yaxis()
    counts.set_xlabel("states (rejected: frames)")
    counts.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def _ms(value) -> str:
    return "      -" if value is None else f"{value * 1e3:7.2f}"


def format_network(network: dict) -> str:
    """A line per link and per robot with watchdog events; the headline figures."""
    steps = network["control_steps_per_s"]
    lines = [f"network: {network['transport']} {network['mode']}, {network['control_steps']} control steps, "
             + (f"{steps:.0f} steps/s" if steps else "no loop time"),
             f"{'link':<22} {'sent':>6} {'recv':>6} {'lost':>5} {'rej':>5} {'lat p50':>7} {'p99':>7} "
             f"{'age p50':>7} {'p99':>7} {'max':>7}  (ms)"]
    for name, link in network["links"].items():
        lat, age = link["latency_s"], link["age_s"]
        lines.append(f"{name[:22]:<22} {link['sent']:>6} {link['received']:>6} {link['lost']:>5} "
                     f"{link['rejected']:>5} {_ms(lat['p50'])} {_ms(lat['p99'])} {_ms(age['p50'])} "
                     f"{_ms(age['p99'])} {_ms(age['max'])}")
    for name, robot in network["robots"].items():
        events = ", ".join(f"{e['event']}{' ' + e['robot'] if 'robot' in e else ''} at {e['t']:.3f} s"
                           for e in robot["watchdog"][:4])
        if events:
            more = len(robot["watchdog"]) - 4
            lines.append(f"{name}: {events}{f' (+{more})' if more > 0 else ''}"[:100])
    return "\n".join(lines)
