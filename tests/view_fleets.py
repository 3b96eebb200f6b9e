"""Scenarios for the view tests: a leader and 7 l-phi followers at 50 Hz, started off formation."""
from nonholo.sim.files import load_scenario


def chain_toml(duration: float, followers: int = 7) -> str:
    text = (f'name = "leader-and-{followers}"\n[simulation]\nduration = {duration}\ndt = 0.02\n'
            'control_period = 0.02\n[reference]\nkind = "eight"\n[[robots]]\nname = "leader"\n'
            'controller = "dynamic-feedback"\ngains = { kp = 1.0, kd = 0.7 }\n'
            'start = [0.0, 0.0, 0.4636476090008061]\n')
    for i in range(1, followers + 1):
        parent = "leader" if i == 1 else f"f{i - 1}"
        text += (f'[[robots]]\nname = "f{i}"\nformation = "separation-bearing"\nleader = "{parent}"\nl = 2.0\n'
                 f'phi = "pi/3"\nstart_relative = [-3.0, 0.5, 0.2]\n')
    return text


def chain(tmp_path, duration: float = 4.0):
    """(file, scenario) of the leader-and-7 fleet."""
    path = tmp_path / "chain.toml"
    path.write_text(chain_toml(duration))
    return path, load_scenario(path)
