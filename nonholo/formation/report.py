"""Text summary of a formation run (``nonholo run`` without ``--json``)."""
from __future__ import annotations


def _fmt(value) -> str:
    return "-" if value is None else f"{value:.4g}"


def format_formation_summary(summary: dict) -> str:
    sim = summary["simulation"]
    lines = [f"{summary['scenario']}: {len(summary['robots'])} robots, {sim['duration']:.6g} s, {sim['steps']} steps of "
             f"{sim['dt']:.4g} s ({sim['method']}, up to {sim['max_substeps']} sub-steps), {sim['elapsed_s']:.3f} s",
             f"evaluation order (parents first): {' -> '.join(summary['order'])}"]
    for name, robot in summary["robots"].items():
        peaks = f"peak v {robot['control']['peak_v']:.3g} m/s, peak w {robot['control']['peak_omega']:.3g} rad/s"
        if robot["role"] == "leader" and "posture" in robot:
            p = robot["posture"]
            lines.append(f"  {name:<14} posture {robot['controller']:<26} goal distance final {_fmt(p['position_error']['final'])} m "
                         f"(max {_fmt(p['position_error']['max'])}), heading error final {_fmt(p['heading_error']['final'])} rad; {peaks}")
            if "note" in p:
                lines.append(f"  {'':<14} note: {p['note']}")
        elif robot["role"] == "leader":
            e = robot["error"]
            lines.append(f"  {name:<14} leader  {robot['controller']:<26} position error mean {_fmt(e['mean'])} m, "
                         f"max {_fmt(e['max'])}, final {_fmt(e['final'])}; {peaks}")
        else:
            f = robot["formation"]
            errors = ", ".join(f"{key[:-6]} error mean {_fmt(v['mean'])} max {_fmt(v['max'])} final {_fmt(v['final'])}"
                               for key, v in f.items() if key.endswith("_error"))
            lines.append(f"  {name:<14} {robot['formation_law']:<22} of {', '.join(f['leaders'])}: {errors}; {peaks}")
            s = f["safety"]
            extra = f", min |sin(g1-g2)| {_fmt(s['min_abs_sin_gamma_difference'])}" if "min_abs_sin_gamma_difference" in s else ""
            lines.append(f"  {'':<14} closest robot {_fmt(s['min_distance'])} m at t={_fmt(s['min_distance_time'])} s, "
                         f"{_fmt(s['time_below_2d'])} s below 2d{extra}")
            for change in f["settling"]:
                parts = [f"{k.replace('_settling_time', '')} settles in {_fmt(v)} s" for k, v in change.items()
                         if k.endswith("_settling_time")]
                parts += [f"{k.replace('_disturbance', '')} deviates at most {_fmt(v)}" for k, v in change.items()
                          if k.endswith("_disturbance")]
                lines.append(f"  {'':<14} change at {change['at']:g} s ({change['mode']}): {', '.join(parts)}")
    safety = summary["safety"]
    if safety.get("min_distance") is not None:
        lines.append(f"closest pair {' / '.join(safety['min_distance_pair'])}: {safety['min_distance']:.4g} m at "
                     f"t = {safety['min_distance_time']:.4g} s; {safety['time_below_2d']:.4g} s with a pair closer than "
                     f"2d = {safety['two_d']:g} m")
    lines.append("separations in metres, bearings in radians, on the uniform output grid")
    return "\n".join(lines)
